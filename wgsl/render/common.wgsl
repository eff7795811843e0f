// Shared by the render shaders (each includes it): the per-picture uniform block
// and the storage of linear depth.

struct Frame {
    view: mat4x4<f32>,
    proj: mat4x4<f32>,
    // xyz: direction towards the light in view space.
    light: vec4<f32>,
    // x: fluid radius, y: wall radius, z: fixed range min, w: fixed range max.
    sizes: vec4<f32>,
    // rgb: wall colour, a: wall opacity.
    wall_color: vec4<f32>,
    // rgb: fluid colour of the surface style, a: absorption per unit thickness.
    fluid_color: vec4<f32>,
    // x: viewport width, y: height, z: bilateral depth scale, w: filter radius in pixels.
    viewport: vec4<f32>,
    // x: ~(smallest value key), y: largest value key (written by render/range.wgsl),
    // z: 1 when that automatic range is used.
    range_keys: vec4<u32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;

// Linear depth is stored in R32Float or, where that cannot be rendered to, split over the two
// channels of Rg16Float: a half-float part and the half-float remainder.
override SPLIT_DEPTH: bool = false;

fn half_float(v: f32) -> f32 {
    return unpack2x16float(pack2x16float(vec2<f32>(v, 0.0))).x;
}

fn encode_depth(z: f32) -> vec4<f32> {
    if (SPLIT_DEPTH) {
        let high = half_float(z);
        return vec4<f32>(high, z - high, 0.0, 0.0);
    }
    return vec4<f32>(z, 0.0, 0.0, 0.0);
}
