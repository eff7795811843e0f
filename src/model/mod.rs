//! What a scene, its constants and a state are: the scene schema and its validation, the
//! resolved parameters, the particles at t = 0, the kernels, and the state a run reports. No
//! GPU and no files (a scene is loaded from a path by [`import`]).

pub mod builtin;
pub mod check;
pub mod diagnosis;
pub mod import;
pub mod initial;
pub mod kernels;
pub mod lanes;
pub mod lattice;
pub mod mesh;
pub mod numbers;
pub mod overrides;
pub mod params;
pub mod probes;
pub mod real;
pub mod scene;
pub mod state;

pub use initial::{InitialState, SolidRegion};
pub use params::{Grid, Params};
pub use scene::{Boundary, Scene, SceneError, SceneOrigin};
pub use state::{BackendState, DtStats, Health, Snapshot, StepFields};
