//! Pictures: frames drawn offscreen, and the viewer in a real window.

#[path = "../common/mod.rs"]
mod common;

mod render;
mod view;
