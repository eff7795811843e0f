//! Eight values at once: [`Pack`], eight lanes in AVX2 vector registers (one 256-bit register
//! of f32, two of f64), and [`Mask`], one flag per lane.
//!
//! Every operation is the scalar IEEE operation applied lane by lane, in the order the scalar
//! code writes it (no fused multiply-add, no reassociation; comparisons are ordered, so a NaN
//! compares false as in Rust), so each lane's result is the scalar result bit for bit.
//!
//! On x86-64 the operations are AVX instructions: they may only run on a processor that has
//! AVX2, and the CPU path runs them inside `solver::cpu::cell_batches::wide`, which checks the
//! processor first and otherwise takes the scalar loops. Elsewhere they are loops over arrays.

/// Lanes of a pack.
pub const LANES: usize = 8;

use std::ops::{Add, Div, Mul, Sub};

/// A float type with an eight-lane form: f32 in one `__m256`, f64 in two `__m256d`.
pub trait LaneFloat: Copy + Default + PartialOrd + 'static {
    /// Eight values (a mask: every bit of a lane set, or none).
    type V: Copy;
    fn splat(v: Self) -> Self::V;
    fn from_array(a: [Self; LANES]) -> Self::V;
    fn to_array(v: Self::V) -> [Self; LANES];
    fn add(a: Self::V, b: Self::V) -> Self::V;
    fn sub(a: Self::V, b: Self::V) -> Self::V;
    fn mul(a: Self::V, b: Self::V) -> Self::V;
    fn div(a: Self::V, b: Self::V) -> Self::V;
    fn sqrt(a: Self::V) -> Self::V;
    fn lt(a: Self::V, b: Self::V) -> Self::V;
    fn le(a: Self::V, b: Self::V) -> Self::V;
    fn ge(a: Self::V, b: Self::V) -> Self::V;
    /// Not equal, true where either is NaN (Rust's `!=`).
    fn ne(a: Self::V, b: Self::V) -> Self::V;
    fn and(a: Self::V, b: Self::V) -> Self::V;
    fn or(a: Self::V, b: Self::V) -> Self::V;
    /// `!a & b`.
    fn and_not(a: Self::V, b: Self::V) -> Self::V;
    /// `a` where `m`, `b` elsewhere.
    fn select(m: Self::V, a: Self::V, b: Self::V) -> Self::V;
    /// The lanes' sign bits, lane k in bit k.
    fn bits(m: Self::V) -> u32;
    /// The lane numbers 0..8.
    fn iota() -> Self::V;
    /// `values[index[k]][c]` in lane k of the c-th result (each index checked against the slice).
    #[inline(always)]
    fn gather3(values: &[[Self; 3]], index: &[u32; LANES]) -> [Self::V; 3] {
        gather_elements(values, index)
    }
    /// As [`gather3`](Self::gather3), with no index checked.
    ///
    /// # Safety
    /// Every `index[k] + 1` must be below `values.len()` (the eight-lane form reads 16 bytes
    /// from each element: its own 12 and the next one's first 4).
    #[inline(always)]
    unsafe fn gather3_unchecked(values: &[[Self; 3]], index: &[u32; LANES]) -> [Self::V; 3] {
        // SAFETY: every index is inside the slice (the caller's promise).
        unsafe { gather_elements_unchecked(values, index) }
    }
    /// `values[index[k]][c]` in lane k of the c-th result (each index checked against the slice).
    #[inline(always)]
    fn gather4(values: &[[Self; 4]], index: &[u32; LANES]) -> [Self::V; 4] {
        gather_elements(values, index)
    }
}

/// `values[index[k]][c]` in lane k of the c-th result, element by element (each index checked
/// against the slice).
#[inline(always)]
fn gather_elements<T: LaneFloat, const C: usize>(values: &[[T; C]], index: &[u32; LANES]) -> [T::V; C] {
    let mut a = [[T::default(); LANES]; C];
    for k in 0..LANES {
        let v = values[index[k] as usize];
        for c in 0..C {
            a[c][k] = v[c];
        }
    }
    a.map(T::from_array)
}

/// As [`gather_elements`], with no index checked.
///
/// # Safety
/// Every `index[k]` must be below `values.len()`.
#[inline(always)]
unsafe fn gather_elements_unchecked<T: LaneFloat, const C: usize>(values: &[[T; C]], index: &[u32; LANES]) -> [T::V; C] {
    let mut a = [[T::default(); LANES]; C];
    for k in 0..LANES {
        // SAFETY: the caller's promise.
        let v = unsafe { *values.get_unchecked(index[k] as usize) };
        for c in 0..C {
            a[c][k] = v[c];
        }
    }
    a.map(T::from_array)
}


#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{LaneFloat, LANES};
    use std::arch::x86_64::*;

    // SAFETY (every `unsafe` block below): the intrinsics need AVX (AVX2 for none of these
    // float operations beyond AVX), which the callers check before running them (module docs).
    impl LaneFloat for f32 {
        type V = __m256;
        #[inline(always)]
        fn splat(v: f32) -> __m256 {
            unsafe { _mm256_set1_ps(v) }
        }
        #[inline(always)]
        fn from_array(a: [f32; LANES]) -> __m256 {
            unsafe { _mm256_loadu_ps(a.as_ptr()) }
        }
        #[inline(always)]
        fn to_array(v: __m256) -> [f32; LANES] {
            let mut a = [0.0; LANES];
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) };
            a
        }
        #[inline(always)]
        fn add(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_add_ps(a, b) }
        }
        #[inline(always)]
        fn sub(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_sub_ps(a, b) }
        }
        #[inline(always)]
        fn mul(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_mul_ps(a, b) }
        }
        #[inline(always)]
        fn div(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_div_ps(a, b) }
        }
        #[inline(always)]
        fn sqrt(a: __m256) -> __m256 {
            unsafe { _mm256_sqrt_ps(a) }
        }
        #[inline(always)]
        fn lt(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(a, b) }
        }
        #[inline(always)]
        fn le(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(a, b) }
        }
        #[inline(always)]
        fn ge(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_GE_OQ>(a, b) }
        }
        #[inline(always)]
        fn ne(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_NEQ_UQ>(a, b) }
        }
        #[inline(always)]
        fn and(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_and_ps(a, b) }
        }
        #[inline(always)]
        fn or(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_or_ps(a, b) }
        }
        #[inline(always)]
        fn and_not(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_andnot_ps(a, b) }
        }
        #[inline(always)]
        fn select(m: __m256, a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_blendv_ps(b, a, m) }
        }
        #[inline(always)]
        fn bits(m: __m256) -> u32 {
            unsafe { _mm256_movemask_ps(m) as u32 }
        }
        #[inline(always)]
        fn iota() -> __m256 {
            Self::from_array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
        }
        /// Eight loads of 16 bytes and a transpose, instead of 32 loads of 4 bytes.
        #[inline(always)]
        fn gather4(values: &[[f32; 4]], index: &[u32; LANES]) -> [__m256; 4] {
            let row = |k: usize| values[index[k] as usize].as_ptr();
            // SAFETY: each pointer is to an element of the slice, 16 bytes long.
            unsafe { transpose8x4([row(0), row(1), row(2), row(3), row(4), row(5), row(6), row(7)]) }
        }
        /// Eight loads of 16 bytes (the vector and the next one's x, where there is a next one)
        /// and a transpose, instead of 24 loads of 4 bytes, each followed by an insert.
        #[inline(always)]
        fn gather3(values: &[[f32; 3]], index: &[u32; LANES]) -> [__m256; 3] {
            // The element after each one must exist for its 16-byte load.
            let inside = index.iter().fold(true, |ok, &i| ok & ((i as usize) + 1 < values.len()));
            if !inside {
                return super::gather_elements(values, index);
            }
            // SAFETY: just checked.
            unsafe { Self::gather3_unchecked(values, index) }
        }
        #[inline(always)]
        unsafe fn gather3_unchecked(values: &[[f32; 3]], index: &[u32; LANES]) -> [__m256; 3] {
            let base = values.as_ptr().cast::<f32>();
            // SAFETY: index[k] + 1 < len (the caller's promise), so the 16 bytes from element
            // index[k] (its 12 and the first 4 of the next) lie inside the slice.
            let row = |k: usize| unsafe { base.add(3 * index[k] as usize) };
            let [x, y, z, _] = unsafe { transpose8x4([row(0), row(1), row(2), row(3), row(4), row(5), row(6), row(7)]) };
            [x, y, z]
        }
    }

    /// Four floats from each of eight addresses, as four registers of eight lanes (lane k from
    /// `rows[k]`).
    ///
    /// # Safety
    /// Each pointer must be valid for reading 16 bytes; AVX must be available.
    #[inline(always)]
    unsafe fn transpose8x4(rows: [*const f32; LANES]) -> [__m256; 4] {
        let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
        unsafe {
            // Lane k in the low half, lane k + 4 in the high half.
            let t0 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(r0)), _mm_loadu_ps(r4));
            let t1 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(r1)), _mm_loadu_ps(r5));
            let t2 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(r2)), _mm_loadu_ps(r6));
            let t3 = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(r3)), _mm_loadu_ps(r7));
            // A 4 x 4 transpose in each half.
            let xy01 = _mm256_unpacklo_ps(t0, t1);
            let zw01 = _mm256_unpackhi_ps(t0, t1);
            let xy23 = _mm256_unpacklo_ps(t2, t3);
            let zw23 = _mm256_unpackhi_ps(t2, t3);
            [
                _mm256_shuffle_ps::<0x44>(xy01, xy23),
                _mm256_shuffle_ps::<0xEE>(xy01, xy23),
                _mm256_shuffle_ps::<0x44>(zw01, zw23),
                _mm256_shuffle_ps::<0xEE>(zw01, zw23),
            ]
        }
    }

    /// Applies a two-operand `__m256d` intrinsic to both halves.
    macro_rules! halves {
        ($f:ident, $a:expr, $b:expr) => {
            unsafe { ($f($a.0, $b.0), $f($a.1, $b.1)) }
        };
    }

    impl LaneFloat for f64 {
        type V = (__m256d, __m256d);
        #[inline(always)]
        fn splat(v: f64) -> Self::V {
            unsafe { (_mm256_set1_pd(v), _mm256_set1_pd(v)) }
        }
        #[inline(always)]
        fn from_array(a: [f64; LANES]) -> Self::V {
            unsafe { (_mm256_loadu_pd(a.as_ptr()), _mm256_loadu_pd(a.as_ptr().add(4))) }
        }
        #[inline(always)]
        fn to_array(v: Self::V) -> [f64; LANES] {
            let mut a = [0.0; LANES];
            unsafe {
                _mm256_storeu_pd(a.as_mut_ptr(), v.0);
                _mm256_storeu_pd(a.as_mut_ptr().add(4), v.1);
            }
            a
        }
        #[inline(always)]
        fn add(a: Self::V, b: Self::V) -> Self::V {
            halves!(_mm256_add_pd, a, b)
        }
        #[inline(always)]
        fn sub(a: Self::V, b: Self::V) -> Self::V {
            halves!(_mm256_sub_pd, a, b)
        }
        #[inline(always)]
        fn mul(a: Self::V, b: Self::V) -> Self::V {
            halves!(_mm256_mul_pd, a, b)
        }
        #[inline(always)]
        fn div(a: Self::V, b: Self::V) -> Self::V {
            halves!(_mm256_div_pd, a, b)
        }
        #[inline(always)]
        fn sqrt(a: Self::V) -> Self::V {
            unsafe { (_mm256_sqrt_pd(a.0), _mm256_sqrt_pd(a.1)) }
        }
        #[inline(always)]
        fn lt(a: Self::V, b: Self::V) -> Self::V {
            unsafe { (_mm256_cmp_pd::<_CMP_LT_OQ>(a.0, b.0), _mm256_cmp_pd::<_CMP_LT_OQ>(a.1, b.1)) }
        }
        #[inline(always)]
        fn le(a: Self::V, b: Self::V) -> Self::V {
            unsafe { (_mm256_cmp_pd::<_CMP_LE_OQ>(a.0, b.0), _mm256_cmp_pd::<_CMP_LE_OQ>(a.1, b.1)) }
        }
        #[inline(always)]
        fn ge(a: Self::V, b: Self::V) -> Self::V {
            unsafe { (_mm256_cmp_pd::<_CMP_GE_OQ>(a.0, b.0), _mm256_cmp_pd::<_CMP_GE_OQ>(a.1, b.1)) }
        }
        #[inline(always)]
        fn ne(a: Self::V, b: Self::V) -> Self::V {
            unsafe { (_mm256_cmp_pd::<_CMP_NEQ_UQ>(a.0, b.0), _mm256_cmp_pd::<_CMP_NEQ_UQ>(a.1, b.1)) }
        }
        #[inline(always)]
        fn and(a: Self::V, b: Self::V) -> Self::V {
            halves!(_mm256_and_pd, a, b)
        }
        #[inline(always)]
        fn or(a: Self::V, b: Self::V) -> Self::V {
            halves!(_mm256_or_pd, a, b)
        }
        #[inline(always)]
        fn and_not(a: Self::V, b: Self::V) -> Self::V {
            halves!(_mm256_andnot_pd, a, b)
        }
        #[inline(always)]
        fn select(m: Self::V, a: Self::V, b: Self::V) -> Self::V {
            unsafe { (_mm256_blendv_pd(b.0, a.0, m.0), _mm256_blendv_pd(b.1, a.1, m.1)) }
        }
        #[inline(always)]
        fn bits(m: Self::V) -> u32 {
            unsafe { (_mm256_movemask_pd(m.0) | (_mm256_movemask_pd(m.1) << 4)) as u32 }
        }
        #[inline(always)]
        fn iota() -> Self::V {
            Self::from_array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
        }
    }
}

/// Elsewhere the lanes are plain arrays (the compiler vectorises what it can); a mask lane is
/// 1 where set and 0 where not.
#[cfg(not(target_arch = "x86_64"))]
mod portable {
    use super::{LaneFloat, LANES};

    macro_rules! array_lanes {
        ($t:ty) => {
            impl LaneFloat for $t {
                type V = [$t; LANES];
                #[inline(always)]
                fn splat(v: $t) -> Self::V {
                    [v; LANES]
                }
                #[inline(always)]
                fn from_array(a: [$t; LANES]) -> Self::V {
                    a
                }
                #[inline(always)]
                fn to_array(v: Self::V) -> [$t; LANES] {
                    v
                }
                #[inline(always)]
                fn add(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| a[k] + b[k])
                }
                #[inline(always)]
                fn sub(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| a[k] - b[k])
                }
                #[inline(always)]
                fn mul(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| a[k] * b[k])
                }
                #[inline(always)]
                fn div(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| a[k] / b[k])
                }
                #[inline(always)]
                fn sqrt(a: Self::V) -> Self::V {
                    a.map(|v| v.sqrt())
                }
                #[inline(always)]
                fn lt(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if a[k] < b[k] { 1.0 } else { 0.0 })
                }
                #[inline(always)]
                fn le(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if a[k] <= b[k] { 1.0 } else { 0.0 })
                }
                #[inline(always)]
                fn ge(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if a[k] >= b[k] { 1.0 } else { 0.0 })
                }
                #[inline(always)]
                fn ne(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if a[k] != b[k] { 1.0 } else { 0.0 })
                }
                #[inline(always)]
                fn and(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if a[k] != 0.0 && b[k] != 0.0 { 1.0 } else { 0.0 })
                }
                #[inline(always)]
                fn or(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if a[k] != 0.0 || b[k] != 0.0 { 1.0 } else { 0.0 })
                }
                #[inline(always)]
                fn and_not(a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if a[k] == 0.0 && b[k] != 0.0 { 1.0 } else { 0.0 })
                }
                #[inline(always)]
                fn select(m: Self::V, a: Self::V, b: Self::V) -> Self::V {
                    std::array::from_fn(|k| if m[k] != 0.0 { a[k] } else { b[k] })
                }
                #[inline(always)]
                fn bits(m: Self::V) -> u32 {
                    (0..LANES).fold(0, |bits, k| bits | (((m[k] != 0.0) as u32) << k))
                }
                #[inline(always)]
                fn iota() -> Self::V {
                    [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
                }
            }
        };
    }
    array_lanes!(f32);
    array_lanes!(f64);
}

/// Eight values of `R`, one per lane.
#[derive(Clone, Copy)]
pub struct Pack<R: LaneFloat>(pub R::V);

/// One flag per lane of a [`Pack`] of `R`.
#[derive(Clone, Copy)]
pub struct Mask<R: LaneFloat>(R::V);

impl<R: LaneFloat> Pack<R> {
    #[inline(always)]
    pub fn splat(v: R) -> Self {
        Pack(R::splat(v))
    }
    #[inline(always)]
    pub fn zero() -> Self {
        Self::splat(R::default())
    }
    #[inline(always)]
    pub fn from_array(a: [R; LANES]) -> Self {
        Pack(R::from_array(a))
    }
    #[inline(always)]
    pub fn to_array(self) -> [R; LANES] {
        R::to_array(self.0)
    }
    /// `values[index[k]]` in lane k (each index checked against the slice).
    #[inline(always)]
    pub fn gather(values: &[R], index: &[u32; LANES]) -> Self {
        let mut a = [R::default(); LANES];
        for k in 0..LANES {
            a[k] = values[index[k] as usize];
        }
        Self::from_array(a)
    }
    /// As [`gather`](Self::gather), with no index checked.
    ///
    /// # Safety
    /// Every `index[k]` must be below `values.len()`.
    #[inline(always)]
    pub unsafe fn gather_unchecked(values: &[R], index: &[u32; LANES]) -> Self {
        // SAFETY: the caller's promise.
        Self::from_array(std::array::from_fn(|k| unsafe { *values.get_unchecked(index[k] as usize) }))
    }
    /// `values[first..first + 8]`.
    #[inline(always)]
    pub fn load(values: &[R], first: usize) -> Self {
        let v: &[R; LANES] = values[first..first + LANES].try_into().expect("eight values");
        Self::from_array(*v)
    }
    #[inline(always)]
    pub fn sqrt(self) -> Self {
        Pack(R::sqrt(self.0))
    }
    #[inline(always)]
    pub fn lt(self, o: Self) -> Mask<R> {
        Mask(<R as LaneFloat>::lt(self.0, o.0))
    }
    #[inline(always)]
    pub fn le(self, o: Self) -> Mask<R> {
        Mask(<R as LaneFloat>::le(self.0, o.0))
    }
    #[inline(always)]
    pub fn ge(self, o: Self) -> Mask<R> {
        Mask(<R as LaneFloat>::ge(self.0, o.0))
    }
    #[inline(always)]
    pub fn ne(self, o: Self) -> Mask<R> {
        Mask(<R as LaneFloat>::ne(self.0, o.0))
    }
    /// `a` in the lanes where `m` is set, `b` elsewhere.
    #[inline(always)]
    pub fn select(m: Mask<R>, a: Self, b: Self) -> Self {
        Pack(R::select(m.0, a.0, b.0))
    }
}

impl<R: LaneFloat> Mask<R> {
    /// The lanes below `count`.
    #[inline(always)]
    pub fn first(count: usize) -> Self {
        let limit: [R; LANES] = R::to_array(R::iota());
        // iota's lane `count` (or 8): a lane is set when its number is below it.
        let bound = if count >= LANES { R::splat(limit[LANES - 1]) } else { R::splat(limit[count]) };
        if count >= LANES {
            Mask(<R as LaneFloat>::le(R::iota(), bound))
        } else {
            Mask(<R as LaneFloat>::lt(R::iota(), bound))
        }
    }
    #[inline(always)]
    pub fn and(self, o: Self) -> Self {
        Mask(R::and(self.0, o.0))
    }
    #[inline(always)]
    pub fn or(self, o: Self) -> Self {
        Mask(R::or(self.0, o.0))
    }
    /// The lanes not set in `self` but set in `o`.
    #[inline(always)]
    pub fn and_not(self, o: Self) -> Self {
        Mask(R::and_not(self.0, o.0))
    }
    /// Lane k in bit k.
    #[inline(always)]
    pub fn bits(self) -> u32 {
        R::bits(self.0)
    }
}

macro_rules! lane_op {
    ($trait:ident, $method:ident) => {
        impl<R: LaneFloat> $trait for Pack<R> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, o: Self) -> Self {
                Pack(R::$method(self.0, o.0))
            }
        }
    };
}
lane_op!(Add, add);
lane_op!(Sub, sub);
lane_op!(Mul, mul);
lane_op!(Div, div);

/// Eight 3-vectors, one per lane, as three packs (structure of arrays).
#[derive(Clone, Copy)]
pub struct PackV3<R: LaneFloat> {
    pub x: Pack<R>,
    pub y: Pack<R>,
    pub z: Pack<R>,
}

impl<R: LaneFloat> PackV3<R> {
    #[inline(always)]
    pub fn zero() -> Self {
        PackV3 { x: Pack::zero(), y: Pack::zero(), z: Pack::zero() }
    }
    #[inline(always)]
    pub fn splat(v: [R; 3]) -> Self {
        PackV3 { x: Pack::splat(v[0]), y: Pack::splat(v[1]), z: Pack::splat(v[2]) }
    }
    /// `values[index[k]]` in lane k (each index checked against the slice).
    #[inline(always)]
    pub fn gather(values: &[[R; 3]], index: &[u32; LANES]) -> Self {
        let [x, y, z] = R::gather3(values, index);
        PackV3 { x: Pack(x), y: Pack(y), z: Pack(z) }
    }
    /// As [`gather`](Self::gather), with no index checked.
    ///
    /// # Safety
    /// Every `index[k] + 1` must be below `values.len()` (see [`LaneFloat::gather3_unchecked`]).
    #[inline(always)]
    pub unsafe fn gather_unchecked(values: &[[R; 3]], index: &[u32; LANES]) -> Self {
        // SAFETY: the caller's promise.
        let [x, y, z] = unsafe { R::gather3_unchecked(values, index) };
        PackV3 { x: Pack(x), y: Pack(y), z: Pack(z) }
    }
    /// `values[index[k]]` in lane k: the vector from its first three components and the pack of
    /// the fourth.
    #[inline(always)]
    pub fn gather_with_w(values: &[[R; 4]], index: &[u32; LANES]) -> (Self, Pack<R>) {
        let [x, y, z, w] = R::gather4(values, index);
        (PackV3 { x: Pack(x), y: Pack(y), z: Pack(z) }, Pack(w))
    }
    /// The vectors of the lanes.
    #[inline(always)]
    pub fn to_arrays(self) -> [[R; 3]; LANES] {
        let (x, y, z) = (self.x.to_array(), self.y.to_array(), self.z.to_array());
        let mut out = [[R::default(); 3]; LANES];
        for k in 0..LANES {
            out[k] = [x[k], y[k], z[k]];
        }
        out
    }
    /// As the scalar dot product: x x' + y y' + z z', summed left to right.
    #[inline(always)]
    pub fn dot(self, o: Self) -> Pack<R> {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// The lanes whose vector is not (0, 0, 0), as the scalar `v != V3::zero()` (a NaN component
    /// counts as not zero).
    #[inline(always)]
    pub fn nonzero(self) -> Mask<R> {
        let zero = Pack::zero();
        self.x.ne(zero).or(self.y.ne(zero)).or(self.z.ne(zero))
    }
    #[inline(always)]
    pub fn scale(self, s: Pack<R>) -> Self {
        PackV3 { x: self.x * s, y: self.y * s, z: self.z * s }
    }
    #[inline(always)]
    pub fn select(m: Mask<R>, a: Self, b: Self) -> Self {
        PackV3 { x: Pack::select(m, a.x, b.x), y: Pack::select(m, a.y, b.y), z: Pack::select(m, a.z, b.z) }
    }
}

impl<R: LaneFloat> Add for PackV3<R> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        PackV3 { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
    }
}

impl<R: LaneFloat> Sub for PackV3<R> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        PackV3 { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn each_lane_is_the_scalar_operation<R: LaneFloat + num_traits::Float + std::fmt::Debug>(a: [R; 8], b: [R; 8]) {
        let (pa, pb) = (Pack::from_array(a), Pack::from_array(b));
        let same = |x: Pack<R>, f: &dyn Fn(R, R) -> R| {
            let x = x.to_array();
            for k in 0..LANES {
                let want = f(a[k], b[k]);
                assert!(x[k] == want || (x[k].is_nan() && want.is_nan()), "lane {k}: {:?} against {:?}", x[k], want);
            }
        };
        same(pa + pb, &|x, y| x + y);
        same(pa - pb, &|x, y| x - y);
        same(pa * pb, &|x, y| x * y);
        same(pa / pb, &|x, y| x / y);
        same(pa.sqrt(), &|x, _| x.sqrt());
        for k in 0..LANES {
            assert_eq!(pa.lt(pb).bits() >> k & 1 == 1, a[k] < b[k]);
            assert_eq!(pa.le(pb).bits() >> k & 1 == 1, a[k] <= b[k]);
            assert_eq!(pa.ge(pb).bits() >> k & 1 == 1, a[k] >= b[k]);
            assert_eq!(pa.ne(pb).bits() >> k & 1 == 1, a[k] != b[k]);
        }
        for count in 0..=LANES {
            assert_eq!(Mask::<R>::first(count).bits(), (1u32 << count) - 1);
        }
        let rows: Vec<[R; 4]> = (0..LANES).map(|k| [a[k], b[k], a[(k + 1) % LANES], b[(k + 3) % LANES]]).collect();
        let index = [3, 1, 4, 1, 5, 2, 6, 0];
        let (v, w) = PackV3::gather_with_w(&rows, &index);
        let (x, y, z, w) = (v.x.to_array(), v.y.to_array(), v.z.to_array(), w.to_array());
        for k in 0..LANES {
            let want = rows[index[k] as usize];
            let got = [x[k], y[k], z[k], w[k]];
            for c in 0..4 {
                assert!(got[c] == want[c] || (got[c].is_nan() && want[c].is_nan()), "gather lane {k} component {c}");
            }
        }
        // Three components: 16-byte loads where an element follows, the last element one by one.
        let points: Vec<[R; 3]> = (0..LANES).map(|k| [a[k], b[k], a[(k + 5) % LANES]]).collect();
        for index in [[3, 1, 4, 1, 5, 2, 6, 0], [7, 0, 7, 2, 1, 6, 5, 3]] {
            let v = PackV3::gather(&points, &index);
            let (x, y, z) = (v.x.to_array(), v.y.to_array(), v.z.to_array());
            for k in 0..LANES {
                let (want, got) = (points[index[k] as usize], [x[k], y[k], z[k]]);
                for c in 0..3 {
                    assert!(got[c] == want[c] || (got[c].is_nan() && want[c].is_nan()), "gather of three, lane {k} component {c}");
                }
            }
        }
        let zero = R::default();
        let nonzero = PackV3 { x: pa, y: pb.sqrt(), z: pa }.nonzero().bits();
        for k in 0..LANES {
            assert_eq!(nonzero >> k & 1 == 1, [a[k], b[k].sqrt(), a[k]] != [zero; 3], "nonzero lane {k}");
        }
        let m = Mask::<R>::first(3);
        assert_eq!(m.and_not(Mask::first(5)).bits(), 0b11000);
        let chosen = Pack::select(m, pa, pb).to_array();
        for k in 0..LANES {
            let want = if k < 3 { a[k] } else { b[k] };
            assert!(chosen[k] == want || (want.is_nan() && chosen[k].is_nan()));
        }
    }

    #[test]
    fn lanes_match_scalar_operations() {
        #[cfg(target_arch = "x86_64")]
        if !is_x86_feature_detected!("avx2") {
            return;
        }
        let nan = f64::NAN;
        let a = [1.5, -2.0, 3.25, 0.0, nan, 7.0, 1e-30, -0.0];
        let b = [0.5, 3.0, -1.0, 2.0, 1.0, f64::INFINITY, 3.0, 0.0];
        each_lane_is_the_scalar_operation::<f64>(a, b);
        each_lane_is_the_scalar_operation::<f32>(a.map(|v| v as f32), b.map(|v| v as f32));
    }
}
