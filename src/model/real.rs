//! The floating-point type the CPU path is generic over (f32 to mirror the GPU, f64 as the judge)
//! and a minimal 3-vector over it.

use super::lanes::LaneFloat;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// A float the CPU solver can run in. `f64` is the reference; `f32` mirrors the GPU's arithmetic.
pub trait Real:
    num_traits::Float + num_traits::FromPrimitive + Send + Sync + Default + std::fmt::Debug + std::iter::Sum + LaneFloat + bytemuck::Pod + 'static
{
    /// Converts a scene constant (always f64) into this type.
    fn of(value: f64) -> Self {
        Self::from_f64(value).expect("f64 converts to any float")
    }
    /// Widens to f64 for output and comparison.
    fn to64(self) -> f64 {
        self.to_f64().expect("float converts to f64")
    }
}
impl Real for f32 {}
impl Real for f64 {}

/// A 3-vector of `R`, stored as three consecutive values (the CPU twin of a WGSL `vec3`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(transparent)]
pub struct V3<R>(pub [R; 3]);

/// The vectors as plain arrays, without a copy.
pub fn as_arrays<R>(v: &[V3<R>]) -> &[[R; 3]] {
    // SAFETY: V3<R> is a transparent wrapper of [R; 3]: the same size, alignment and layout.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<[R; 3]>(), v.len()) }
}

impl<R: Real> V3<R> {
    pub fn zero() -> Self {
        V3([R::zero(); 3])
    }
    pub fn new(x: R, y: R, z: R) -> Self {
        V3([x, y, z])
    }
    pub fn from64(v: [f64; 3]) -> Self {
        V3([R::of(v[0]), R::of(v[1]), R::of(v[2])])
    }
    pub fn to64(self) -> [f64; 3] {
        [self.0[0].to64(), self.0[1].to64(), self.0[2].to64()]
    }
    pub fn dot(self, o: Self) -> R {
        self.0[0] * o.0[0] + self.0[1] * o.0[1] + self.0[2] * o.0[2]
    }
    pub fn length_squared(self) -> R {
        self.dot(self)
    }
    pub fn length(self) -> R {
        self.length_squared().sqrt()
    }
    pub fn x(self) -> R {
        self.0[0]
    }
    pub fn y(self) -> R {
        self.0[1]
    }
    pub fn z(self) -> R {
        self.0[2]
    }
    pub fn is_finite(self) -> bool {
        self.0.iter().all(|c| c.is_finite())
    }
}

impl<R: Real> Add for V3<R> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        V3([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }
}
impl<R: Real> Sub for V3<R> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        V3([self.0[0] - o.0[0], self.0[1] - o.0[1], self.0[2] - o.0[2]])
    }
}
impl<R: Real> Mul<R> for V3<R> {
    type Output = Self;
    fn mul(self, s: R) -> Self {
        V3([self.0[0] * s, self.0[1] * s, self.0[2] * s])
    }
}
impl<R: Real> Div<R> for V3<R> {
    type Output = Self;
    fn div(self, s: R) -> Self {
        V3([self.0[0] / s, self.0[1] / s, self.0[2] / s])
    }
}
impl<R: Real> Neg for V3<R> {
    type Output = Self;
    fn neg(self) -> Self {
        V3([-self.0[0], -self.0[1], -self.0[2]])
    }
}
impl<R: Real> AddAssign for V3<R> {
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<R: Real> SubAssign for V3<R> {
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}
