// Particles drawn as instanced sphere impostors: each instance is a camera-facing quad whose
// fragments intersect the view ray with the particle's sphere, so silhouettes and depth are
// those of true spheres (the impostor technique of Gumhold 2003, in a simple ray-cast form).
// The same vertex stage feeds three fragment stages: shaded colour (particle style), linear
// depth and thickness (the first passes of the surface style, render/surface.wgsl).

//! include render/common.wgsl


struct Impostor {
    @builtin(position) clip: vec4<f32>,
    // The quad point and the sphere centre in view space.
    @location(0) point: vec3<f32>,
    @location(1) center: vec3<f32>,
    @location(2) radius: f32,
    @location(3) color: vec4<f32>,
}

// Viridis (matplotlib, van der Walt & Smith 2015) sampled at eight even steps, sRGB.
const VIRIDIS = array<vec3<f32>, 8>(
    vec3<f32>(0.267, 0.004, 0.329),
    vec3<f32>(0.275, 0.196, 0.494),
    vec3<f32>(0.212, 0.361, 0.553),
    vec3<f32>(0.153, 0.498, 0.557),
    vec3<f32>(0.122, 0.631, 0.529),
    vec3<f32>(0.290, 0.757, 0.427),
    vec3<f32>(0.624, 0.855, 0.227),
    vec3<f32>(0.992, 0.906, 0.145),
);

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    return select(pow((c + 0.055) / 1.055, vec3<f32>(2.4)), c / 12.92, c <= vec3<f32>(0.04045));
}

fn viridis(t: f32) -> vec3<f32> {
    let x = clamp(t, 0.0, 1.0) * 7.0;
    let i = min(u32(x), 6u);
    let c = mix(VIRIDIS[i], VIRIDIS[i + 1u], x - f32(i));
    // The render target is sRGB: the blend hardware expects linear values.
    return srgb_to_linear(c);
}

// Inverse of the order-preserving float-to-key map of render/range.wgsl.
fn key_to_float(k: u32) -> f32 {
    if ((k & 0x80000000u) != 0u) {
        return bitcast<f32>(k ^ 0x80000000u);
    }
    return bitcast<f32>(~k);
}

fn colour_of(value: f32) -> vec3<f32> {
    var lo = frame.sizes.z;
    var hi = frame.sizes.w;
    if (frame.range_keys.z == 1u) {
        lo = key_to_float(~frame.range_keys.x);
        hi = key_to_float(frame.range_keys.y);
    }
    let span = hi - lo;
    var t = 0.5;
    if (span > 0.0) {
        t = (value - lo) / span;
    }
    return viridis(t);
}

// Quad corners of the six vertices of two triangles.
fn corner(v: u32) -> vec2<f32> {
    let corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    return corners[v];
}

fn impostor(v: u32, world: vec3<f32>, radius: f32, color: vec4<f32>) -> Impostor {
    let center = (frame.view * vec4<f32>(world, 1.0)).xyz;
    // The quad sits in front of the sphere, enlarged so that it covers the sphere's silhouette
    // seen in perspective (off-axis silhouettes are ellipses up to 1/cos of the field angle wider).
    let dist = max(length(center), 1e-6);
    let grow = 1.5 / sqrt(max(1.0 - (radius / dist) * (radius / dist), 0.05));
    let quad = center + vec3<f32>(corner(v) * radius * grow, radius);
    var out: Impostor;
    out.clip = frame.proj * vec4<f32>(quad, 1.0);
    out.point = quad;
    out.center = center;
    out.radius = radius;
    out.color = color;
    return out;
}

@vertex
fn vs_fluid_vector(@builtin(vertex_index) v: u32, @location(0) position: vec4<f32>, @location(1) field: vec4<f32>) -> Impostor {
    return impostor(v, position.xyz, frame.sizes.x, vec4<f32>(colour_of(length(field.xyz)), 1.0));
}

@vertex
fn vs_fluid_scalar(@builtin(vertex_index) v: u32, @location(0) position: vec4<f32>, @location(1) field: f32) -> Impostor {
    return impostor(v, position.xyz, frame.sizes.x, vec4<f32>(colour_of(field), 1.0));
}

@vertex
fn vs_wall(@builtin(vertex_index) v: u32, @location(0) position: vec4<f32>) -> Impostor {
    return impostor(v, position.xyz, frame.sizes.y, frame.wall_color);
}

struct Hit {
    point: vec3<f32>,
    normal: vec3<f32>,
    // Length of the chord the ray cuts through the sphere.
    chord: f32,
}

// Ray from the eye (the view-space origin) through the fragment, against the sphere.
fn ray_sphere(in: Impostor) -> Hit {
    let dir = normalize(in.point);
    let b = dot(dir, in.center);
    let disc = b * b - dot(in.center, in.center) + in.radius * in.radius;
    if (disc < 0.0) {
        discard;
    }
    let root = sqrt(disc);
    let t = b - root;
    var hit: Hit;
    hit.point = dir * t;
    hit.normal = (hit.point - in.center) / in.radius;
    hit.chord = 2.0 * root;
    return hit;
}

fn depth_of(point: vec3<f32>) -> f32 {
    let clip = frame.proj * vec4<f32>(point, 1.0);
    return clip.z / clip.w;
}

struct Shaded {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
}

@fragment
fn fs_shaded(in: Impostor) -> Shaded {
    let hit = ray_sphere(in);
    let l = normalize(frame.light.xyz);
    let diffuse = max(dot(hit.normal, l), 0.0);
    let half_vector = normalize(l - normalize(hit.point));
    let specular = pow(max(dot(hit.normal, half_vector), 0.0), 48.0);
    let rgb = in.color.rgb * (0.3 + 0.7 * diffuse) + vec3<f32>(0.25 * specular);
    var out: Shaded;
    out.color = vec4<f32>(rgb, in.color.a);
    out.depth = depth_of(hit.point);
    return out;
}

struct LinearDepth {
    // Distance along the view axis (positive in front of the eye); 0 means empty.
    @location(0) depth: vec4<f32>,
    @builtin(frag_depth) ndc_depth: f32,
}

@fragment
fn fs_linear_depth(in: Impostor) -> LinearDepth {
    let hit = ray_sphere(in);
    var out: LinearDepth;
    out.depth = encode_depth(-hit.point.z);
    out.ndc_depth = depth_of(hit.point);
    return out;
}

@fragment
fn fs_thickness(in: Impostor) -> @location(0) vec4<f32> {
    let hit = ray_sphere(in);
    return vec4<f32>(hit.chord, 0.0, 0.0, 0.0);
}
