//! The perspective camera of rendered frames: from the scene file, or framed automatically.

use crate::model::scene::Scene;
use glam::{Mat4, Vec3, Vec4Swizzles};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
}

/// Centre and radius of the sphere around what the scene shows; near and far planes follow it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: Vec3,
    pub max: Vec3,
}

impl Bounds {
    pub fn of_scene(scene: &Scene) -> Self {
        let (lo, hi) = scene.view_bounds();
        Bounds { min: Vec3::from(lo.map(|v| v as f32)), max: Vec3::from(hi.map(|v| v as f32)) }
    }
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }
    pub fn radius(&self) -> f32 {
        (0.5 * (self.max - self.min).length()).max(1e-6)
    }
    fn corners(&self) -> [Vec3; 8] {
        std::array::from_fn(|i| {
            Vec3::new(
                if i & 1 == 0 { self.min.x } else { self.max.x },
                if i & 2 == 0 { self.min.y } else { self.max.y },
                if i & 4 == 0 { self.min.z } else { self.max.z },
            )
        })
    }
}

impl Camera {
    /// The scene's camera, or the automatic one; a camera field the scene leaves out is chosen
    /// as the automatic camera chooses it.
    pub fn for_scene(scene: &Scene, aspect: f32) -> Self {
        let bounds = Bounds::of_scene(scene);
        let Some(c) = &scene.camera else {
            return Camera::framing(&bounds, aspect);
        };
        let v = |p: [f64; 3]| Vec3::from(p.map(|x| x as f32));
        let fov_y = (c.fov_degrees as f32).to_radians();
        let target = c.target.map(v);
        let mut cam = match c.eye {
            Some(eye) => Camera { eye: v(eye), target: target.unwrap_or(bounds.center()), up: Vec3::Y, fov_y },
            None => Camera::framing_towards(&bounds, aspect, fov_y, target.unwrap_or(bounds.center())),
        };
        cam.up = v(c.up);
        cam
    }

    /// Looks at the box from the front, a little above and (for boxes that are not thin
    /// slabs) from the side, at the smallest distance that keeps all eight corners inside 90 %
    /// of the picture.
    pub fn framing(bounds: &Bounds, aspect: f32) -> Self {
        Camera::framing_towards(bounds, aspect, 40f32.to_radians(), bounds.center())
    }

    /// [`Camera::framing`] with a field of view of `fov_y` radians, looking at `target`.
    pub fn framing_towards(bounds: &Bounds, aspect: f32, fov_y: f32, target: Vec3) -> Self {
        let size = bounds.max - bounds.min;
        let slab = size.z < 0.25 * size.x.max(size.y);
        let dir = if slab { Vec3::new(0.0, 0.3, 1.0) } else { Vec3::new(0.6, 0.55, 1.0) }.normalize();
        let mut cam = Camera { eye: target + dir, target, up: Vec3::Y, fov_y };
        // The largest corner extent in normalised device coordinates falls as the distance grows:
        // bisect for the distance where it is 0.9.
        let reach = bounds.radius() + (target - bounds.center()).length();
        let (mut near, mut far) = (reach * 0.01, reach * 100.0);
        for _ in 0..60 {
            let d = 0.5 * (near + far);
            cam.eye = target + dir * d;
            let vp = cam.projection(aspect, bounds) * cam.view();
            let fits = bounds.corners().iter().all(|c| {
                let p = vp * c.extend(1.0);
                p.w > 0.0 && (p.xy() / p.w).abs().max_element() <= 0.9
            });
            if fits {
                far = d;
            } else {
                near = d;
            }
        }
        cam.eye = target + dir * far;
        cam
    }

    pub fn view(&self) -> Mat4 {
        Mat4::look_at_rh(self.eye, self.target, self.up)
    }

    /// Perspective with near and far planes around the bounds (wgpu's depth range 0..1).
    pub fn projection(&self, aspect: f32, bounds: &Bounds) -> Mat4 {
        let (near, far) = self.clip_planes(bounds);
        Mat4::perspective_rh(self.fov_y, aspect, near, far)
    }

    fn clip_planes(&self, bounds: &Bounds) -> (f32, f32) {
        let r = bounds.radius();
        let d = (bounds.center() - self.eye).length();
        let far = d + 2.0 * r;
        (((d - 2.0 * r).max(far * 1e-4)), far)
    }

    /// Where a world point lands in a `width` x `height` picture (pixel centres at +0.5), or
    /// None behind the eye.
    pub fn project(&self, p: Vec3, width: u32, height: u32, bounds: &Bounds) -> Option<(f32, f32)> {
        let clip = self.projection(width as f32 / height as f32, bounds) * self.view() * p.extend(1.0);
        if clip.w <= 0.0 {
            return None;
        }
        let ndc = clip.xy() / clip.w;
        Some(((ndc.x + 1.0) * 0.5 * width as f32, (1.0 - ndc.y) * 0.5 * height as f32))
    }

    /// Radius in pixels of a sphere of `radius` at `p` (at the sphere's distance along the view axis).
    pub fn projected_radius(&self, p: Vec3, radius: f32, height: u32, bounds: &Bounds) -> f32 {
        let depth = -(self.view() * p.extend(1.0)).z;
        let proj = self.projection(1.0, bounds);
        radius * proj.y_axis.y * 0.5 * height as f32 / depth.max(1e-6)
    }

    /// Orbits the eye around the target by yaw and pitch (radians), keeping the distance.
    pub fn orbit(&mut self, yaw: f32, pitch: f32) {
        let offset = self.eye - self.target;
        let r = offset.length();
        let mut theta = offset.z.atan2(offset.x) + yaw;
        let mut phi = (offset.y / r).clamp(-1.0, 1.0).asin() + pitch;
        phi = phi.clamp(-1.5, 1.5);
        theta %= std::f32::consts::TAU;
        self.eye = self.target + r * Vec3::new(phi.cos() * theta.cos(), phi.sin(), phi.cos() * theta.sin());
    }

    /// Moves the eye towards (factor < 1) or away from the target.
    pub fn zoom(&mut self, factor: f32) {
        self.eye = self.target + (self.eye - self.target) * factor;
    }
}
