// The mesh style: the reconstructed fluid surface (a triangle mesh with per-vertex normals,
// src/io/surface.rs) drawn opaque and shaded like the surface style: a diffuse light, a specular
// highlight (Blinn-Phong) and a Fresnel reflection of the sky (Schlick's approximation).

//! include render/common.wgsl

struct MeshVertex {
    @builtin(position) clip: vec4<f32>,
    @location(0) view_position: vec3<f32>,
    @location(1) normal: vec3<f32>,
}

@vertex
fn vs_mesh(@location(0) position: vec3<f32>, @location(1) normal: vec3<f32>) -> MeshVertex {
    let v = frame.view * vec4<f32>(position, 1.0);
    var out: MeshVertex;
    out.clip = frame.proj * v;
    out.view_position = v.xyz;
    // The view matrix is a rotation and a translation, so it carries normals unchanged in length.
    out.normal = (frame.view * vec4<f32>(normal, 0.0)).xyz;
    return out;
}

@fragment
fn fs_mesh(in: MeshVertex) -> @location(0) vec4<f32> {
    let v = -normalize(in.view_position);
    // A vertex of only degenerate triangles has no normal: it faces the eye.
    var n = v;
    if (dot(in.normal, in.normal) > 1e-12) {
        n = normalize(in.normal);
    }
    // Both sides of the surface are shaded alike (the mesh is not culled).
    if (dot(n, v) < 0.0) {
        n = -n;
    }
    let l = normalize(frame.light.xyz);
    let diffuse = max(dot(n, l), 0.0);
    let half_vector = normalize(l + v);
    let specular = pow(max(dot(n, half_vector), 0.0), 80.0);
    // Schlick's approximation of the Fresnel term for water (F0 = 0.02).
    let fresnel = 0.02 + 0.98 * pow(1.0 - max(dot(n, v), 0.0), 5.0);
    let sky = vec3<f32>(0.55, 0.62, 0.72);
    let rgb = frame.fluid_color.rgb * (0.35 + 0.65 * diffuse) + fresnel * sky * 0.6 + vec3<f32>(0.6 * specular);
    return vec4<f32>(rgb, 1.0);
}
