//! The GPU's checkpoint state serialised while it is read back: the arrays (in cell order, as
//! [`Backend::save_state`](crate::sim::Backend::save_state) keeps them) one after the other,
//! `chunk` particles at a time, so the host holds one piece instead of every array (52 bytes per
//! particle as f64, plus the readback).

use super::super::{health_of, read_ranges, widen, GpuSolver};
use serde::ser::{Error as _, Serialize, SerializeSeq, Serializer};
use std::cell::RefCell;

/// Serialises exactly as [`crate::sim::BackendState`] does: postcard writes a struct as its
/// fields in order, so these fields are BackendState's, in its order, with the arrays read from
/// the GPU as they are serialised (the tests compare the bytes with the whole-array checkpoint).
#[derive(serde::Serialize)]
struct StateInPieces<'a> {
    kind: &'a str,
    step: u64,
    positions: GpuArray<'a>,
    velocities: GpuArray<'a>,
    ids: GpuArray<'a>,
    non_finite: u64,
    escaped: u64,
    first_bad_step: Option<u64>,
    max_density: f64,
    time: f64,
    dt_min_max_last: [f64; 3],
    gpu_status: &'a [u32],
}

#[derive(Clone, Copy)]
enum Element {
    /// `vec4<f32>` on the GPU, `[f64; 3]` in the state.
    Vec3,
    /// The u32 bits in the w of the positions.
    Ids,
}

/// One particle array on the GPU, serialised as a sequence read back piece by piece.
struct GpuArray<'a> {
    solver: &'a GpuSolver,
    buffer: &'a wgpu::Buffer,
    element: Element,
    chunk: u64,
    /// Why a readback failed (postcard keeps only that a custom error happened).
    failure: &'a RefCell<Option<anyhow::Error>>,
}

impl Serialize for GpuArray<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let n = self.solver.fluid_count as u64;
        let size = 16;
        let mut seq = serializer.serialize_seq(Some(n as usize))?;
        for slot in (0..n).step_by(self.chunk as usize) {
            let count = self.chunk.min(n - slot);
            let data = match read_ranges(&self.solver.ctx, &[(self.buffer, slot * size, count * size)]) {
                Ok(data) => data,
                Err(e) => {
                    *self.failure.borrow_mut() = Some(e);
                    return Err(S::Error::custom("reading the GPU state back failed"));
                }
            };
            match self.element {
                Element::Vec3 => {
                    for v in bytemuck::cast_slice::<u8, [f32; 4]>(&data[0]) {
                        seq.serialize_element(&widen(v))?;
                    }
                }
                Element::Ids => {
                    for p in bytemuck::cast_slice::<u8, [f32; 4]>(&data[0]) {
                        seq.serialize_element(&p[3].to_bits())?;
                    }
                }
            }
        }
        seq.end()
    }
}

impl GpuSolver {
    /// Writes the postcard encoding of the state [`crate::sim::Backend::save_state`] returns
    /// (the same bytes) to `w`, reading the particle arrays back `chunk` particles at a time.
    pub fn write_state_in_pieces(&mut self, w: &mut dyn std::io::Write, chunk: u64) -> anyhow::Result<()> {
        let status = self.counted_status()?;
        let h = health_of(&status);
        let failure = RefCell::new(None);
        let st = &self.state[self.current];
        let array = |buffer, element| GpuArray { solver: self, buffer, element, chunk: chunk.max(1), failure: &failure };
        let state = StateInPieces {
            kind: "gpu",
            step: self.steps,
            positions: array(&st.positions, Element::Vec3),
            velocities: array(&st.velocities, Element::Vec3),
            ids: array(&st.positions, Element::Ids),
            non_finite: h.non_finite,
            escaped: h.escaped,
            first_bad_step: h.first_bad_step,
            max_density: h.max_density,
            time: 0.0,
            dt_min_max_last: [0.0; 3],
            gpu_status: &status,
        };
        let result = postcard::to_io(&state, w);
        drop(state);
        match (result, failure.into_inner()) {
            (Ok(_), _) => Ok(()),
            (Err(_), Some(readback)) => Err(readback),
            (Err(e), None) => Err(anyhow::anyhow!("cannot serialise the state: {e}")),
        }
    }
}
