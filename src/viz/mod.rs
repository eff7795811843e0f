//! Pictures: the renderer (offscreen frames and the window of `wgsph view`) and plots. A solver
//! is reached only through the [`crate::solver::Backend`] trait, or the particle buffers a GPU
//! solver hands out.

pub mod plot;
pub mod probe_plots;
pub mod render;
#[cfg(feature = "view")]
pub mod view;
