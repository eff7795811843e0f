// The surface style: screen-space fluid rendering (van der Laan, Green & Sainz 2009). The
// particle passes (render/particles.wgsl) leave the nearest sphere depth and the summed
// thickness per pixel; here the depth is smoothed with a separable bilateral filter, normals are
// taken from the smoothed depth, and the surface is shaded with a light, a Fresnel reflection
// and a tint that deepens with thickness (Beer-Lambert absorption).

//! include render/common.wgsl

@group(0) @binding(1) var depth_in: texture_2d<f32>;
@group(0) @binding(2) var thickness_in: texture_2d<f32>;

// Blur direction of this pass: (1, 0) or (0, 1).
override BLUR_AXIS_X: bool = true;

struct Fullscreen {
    @builtin(position) clip: vec4<f32>,
}

@vertex
fn vs_fullscreen(@builtin(vertex_index) v: u32) -> Fullscreen {
    // One triangle that covers the viewport.
    let uv = vec2<f32>(f32((v << 1u) & 2u), f32(v & 2u));
    var out: Fullscreen;
    out.clip = vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
    return out;
}

fn load_depth(p: vec2<i32>) -> f32 {
    let size = vec2<i32>(textureDimensions(depth_in));
    let q = clamp(p, vec2<i32>(0), size - 1);
    let d = textureLoad(depth_in, q, 0);
    return d.r + d.g;
}

// One direction of the bilateral filter: a Gaussian in screen space whose width is the
// particle's projected radius, weighted down across depth jumps so silhouettes stay sharp.
@fragment
fn fs_blur(in: Fullscreen) -> @location(0) vec4<f32> {
    let p = vec2<i32>(in.clip.xy);
    let z = load_depth(p);
    if (z <= 0.0) {
        return vec4<f32>(0.0);
    }
    // Projected particle radius in pixels, at this depth.
    let radius_px = clamp(frame.sizes.x * frame.proj[1][1] * 0.5 * frame.viewport.y / z, 1.0, frame.viewport.w);
    let taps = i32(ceil(min(2.0 * radius_px, frame.viewport.w)));
    let sigma = max(radius_px, 0.5);
    let depth_scale = frame.viewport.z;
    var axis = vec2<i32>(0, 1);
    if (BLUR_AXIS_X) {
        axis = vec2<i32>(1, 0);
    }
    var sum = 0.0;
    var weights = 0.0;
    for (var k = -taps; k <= taps; k++) {
        let zk = load_depth(p + axis * k);
        if (zk > 0.0) {
            let spatial = exp(-f32(k * k) / (2.0 * sigma * sigma));
            let dz = (zk - z) / depth_scale;
            let range = exp(-dz * dz);
            sum += zk * spatial * range;
            weights += spatial * range;
        }
    }
    return encode_depth(sum / weights);
}

// The view-space point seen at pixel p at linear depth z.
fn view_point(p: vec2<f32>, z: f32) -> vec3<f32> {
    let ndc = vec2<f32>(p.x / frame.viewport.x * 2.0 - 1.0, 1.0 - p.y / frame.viewport.y * 2.0);
    return vec3<f32>(ndc.x * z / frame.proj[0][0], ndc.y * z / frame.proj[1][1], -z);
}

// The neighbour difference with the smaller depth change, so that normals do not bend over
// silhouettes (one-sided differences, Green 2010).
fn tangent(p: vec2<i32>, axis: vec2<i32>, here: vec3<f32>) -> vec3<f32> {
    let za = load_depth(p + axis);
    let zb = load_depth(p - axis);
    let pa = view_point(vec2<f32>(p + axis) + 0.5, za);
    let pb = view_point(vec2<f32>(p - axis) + 0.5, zb);
    let da = pa - here;
    let db = here - pb;
    if (zb <= 0.0 || (za > 0.0 && abs(da.z) < abs(db.z))) {
        if (za <= 0.0) {
            return vec3<f32>(0.0);
        }
        return da;
    }
    return db;
}

struct Composite {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
}

@fragment
fn fs_composite(in: Fullscreen) -> Composite {
    let p = vec2<i32>(in.clip.xy);
    let z = load_depth(p);
    if (z <= 0.0) {
        discard;
    }
    let here = view_point(vec2<f32>(p) + 0.5, z);
    var dx = tangent(p, vec2<i32>(1, 0), here);
    var dy = tangent(p, vec2<i32>(0, -1), here);
    var n = vec3<f32>(0.0, 0.0, 1.0);
    let c = cross(dx, dy);
    if (dot(c, c) > 0.0) {
        n = normalize(c);
    }
    if (dot(n, here) > 0.0) {
        n = -n;
    }
    let v = -normalize(here);
    let l = normalize(frame.light.xyz);
    let thickness = textureLoad(thickness_in, p, 0).r;
    // Light passing through the fluid keeps exp(-absorption * thickness) of the background.
    let transmit = exp(-frame.fluid_color.a * thickness);
    let background = vec3<f32>(0.02, 0.025, 0.035);
    let body = mix(frame.fluid_color.rgb, background, transmit);
    let diffuse = max(dot(n, l), 0.0);
    let half_vector = normalize(l + v);
    let specular = pow(max(dot(n, half_vector), 0.0), 80.0);
    // Schlick's approximation of the Fresnel term for water (F0 = 0.02).
    let fresnel = 0.02 + 0.98 * pow(1.0 - max(dot(n, v), 0.0), 5.0);
    let sky = vec3<f32>(0.55, 0.62, 0.72);
    let rgb = body * (0.35 + 0.65 * diffuse) + fresnel * sky * 0.6 + vec3<f32>(0.6 * specular);
    var out: Composite;
    out.color = vec4<f32>(rgb, 1.0);
    let clip = frame.proj * vec4<f32>(here, 1.0);
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    return out;
}
