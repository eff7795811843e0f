//! Closed triangle surfaces read from mesh files (Wavefront OBJ, STL), placed in a scene, and
//! the wall particles that line them.
//!
//! A mesh boundary is sampled as a tank's walls are, on a regular lattice of the wall spacing:
//! the lattice points on the wall side of the surface (inside a solid; outside a tank whose
//! fluid is inside) and nearer to it than `layers x spacing` are its wall particles, so a flat
//! face on the lattice gets `layers` layers, the first half a spacing from it, like a
//! container's (the voxel filling of DualSPHysics' GenCase does the same). Which side a point
//! lies on is told by counting the surface's crossings along a ray from it (odd: inside), so
//! the surface must be closed: a file with an edge that is not shared by an even number of
//! triangles is refused.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// A triangle's three corners.
pub type Triangle = [[f64; 3]; 3];

/// The triangles of a mesh file; `extension` (`obj` or `stl`, any case) picks the format.
pub fn parse_mesh(bytes: &[u8], extension: &str) -> Result<Vec<Triangle>, String> {
    let triangles = match extension.to_ascii_lowercase().as_str() {
        "obj" => parse_obj(&String::from_utf8_lossy(bytes))?,
        "stl" => parse_stl(bytes)?,
        other => return Err(format!("has the extension '{other}'; a mesh must be a Wavefront OBJ (.obj) or an STL (.stl) file")),
    };
    if triangles.is_empty() {
        return Err("holds no triangle".into());
    }
    Ok(triangles)
}

/// Wavefront OBJ: `v x y z` vertices and `f` faces of vertex indices (from 1, or negative: from
/// the last vertex read; `v/vt/vn` forms read the `v`); a face of more than three corners is cut
/// into a fan. Other lines (normals, texture coordinates, groups, materials) are skipped.
fn parse_obj(text: &str) -> Result<Vec<Triangle>, String> {
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    // Faces as vertex indices, checked against the vertex count at the end (a face may name a
    // vertex that comes later in the file).
    let mut faces: Vec<(usize, Vec<usize>)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        let line = line.split('#').next().unwrap_or("");
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let mut v = [0.0; 3];
                for c in &mut v {
                    let word = words.next().ok_or_else(|| format!("line {line_no}: a vertex needs three coordinates (v x y z)"))?;
                    *c = word.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| format!("line {line_no}: '{word}' is not a finite number"))?;
                }
                vertices.push(v);
            }
            Some("f") => {
                let mut corners = Vec::new();
                for word in words {
                    let index = word.split('/').next().unwrap_or("");
                    let i: i64 = index.parse().map_err(|_| format!("line {line_no}: '{word}' is not a vertex index"))?;
                    let resolved = match i {
                        0 => return Err(format!("line {line_no}: vertex index 0; OBJ indices count from 1")),
                        i if i > 0 => (i - 1) as usize,
                        i => vertices.len().checked_sub(i.unsigned_abs() as usize).ok_or_else(|| {
                            format!("line {line_no}: vertex index {i} reaches before the first vertex ({} read so far)", vertices.len())
                        })?,
                    };
                    corners.push(resolved);
                }
                if corners.len() < 3 {
                    return Err(format!("line {line_no}: a face needs at least three vertices, has {}", corners.len()));
                }
                faces.push((line_no, corners));
            }
            _ => {}
        }
    }
    let mut triangles = Vec::new();
    for (line_no, corners) in faces {
        if let Some(&bad) = corners.iter().find(|&&i| i >= vertices.len()) {
            return Err(format!("line {line_no}: vertex index {} is past the last vertex ({} in the file)", bad + 1, vertices.len()));
        }
        for k in 1..corners.len() - 1 {
            triangles.push([vertices[corners[0]], vertices[corners[k]], vertices[corners[k + 1]]]);
        }
    }
    Ok(triangles)
}

/// STL, binary (an 80-byte header, a triangle count, 50 bytes a triangle) or ASCII (`vertex x
/// y z` lines, three a facet). A file whose size is that of its binary count is binary, even
/// when its header starts with `solid` as some writers' do.
fn parse_stl(bytes: &[u8]) -> Result<Vec<Triangle>, String> {
    if bytes.len() >= 84 {
        let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if count.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len()) {
            let mut triangles = Vec::with_capacity(count);
            for t in 0..count {
                let at = 84 + 50 * t + 12; // after the facet's normal
                let f = |k: usize| f32::from_le_bytes(bytes[at + 4 * k..at + 4 * k + 4].try_into().expect("four bytes")) as f64;
                let tri: Triangle = std::array::from_fn(|c| std::array::from_fn(|a| f(3 * c + a)));
                if tri.iter().flatten().any(|x| !x.is_finite()) {
                    return Err(format!("triangle {t} of the binary STL has a coordinate that is not a finite number"));
                }
                triangles.push(tri);
            }
            return Ok(triangles);
        }
    }
    let text = String::from_utf8_lossy(bytes);
    if !text.trim_start().starts_with("solid") {
        return Err(format!(
            "is neither a binary STL (its {} bytes are not 84 + 50 per triangle of its count) nor an ASCII STL (starting with 'solid')",
            bytes.len()));
    }
    let mut corners = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if words.next() != Some("vertex") {
            continue;
        }
        let mut v = [0.0; 3];
        for c in &mut v {
            let word = words.next().ok_or_else(|| format!("line {}: a vertex needs three coordinates (vertex x y z)", n + 1))?;
            *c = word.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| format!("line {}: '{word}' is not a finite number", n + 1))?;
        }
        corners.push(v);
    }
    if corners.len() % 3 != 0 {
        return Err(format!("has {} vertex lines, not three for each facet", corners.len()));
    }
    Ok(corners.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// An edge of the surface that is not shared by an even number of triangles (so the surface
/// has a hole or a loose flap there): the count of such edges and the midpoint of one. Corners
/// are matched by their exact coordinates, as STL files repeat them.
pub fn open_edges(triangles: &[Triangle]) -> Option<(usize, [f64; 3])> {
    let key = |p: [f64; 3]| p.map(|c| (c + 0.0).to_bits());
    let mut ids: HashMap<[u64; 3], u32> = HashMap::new();
    let mut corners: Vec<[f64; 3]> = Vec::new();
    let mut id = |p: [f64; 3]| {
        *ids.entry(key(p)).or_insert_with(|| {
            corners.push(p);
            (corners.len() - 1) as u32
        })
    };
    let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
    for t in triangles {
        let v = t.map(&mut id);
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            continue;
        }
        for (a, b) in [(v[0], v[1]), (v[1], v[2]), (v[2], v[0])] {
            *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    let mut odd: Vec<(u32, u32)> = uses.into_iter().filter(|(_, n)| n % 2 == 1).map(|(e, _)| e).collect();
    odd.sort_unstable();
    let &(a, b) = odd.first()?;
    let (p, q) = (corners[a as usize], corners[b as usize]);
    Some((odd.len(), std::array::from_fn(|k| 0.5 * (p[k] + q[k]))))
}

/// Where a mesh sits in the scene: its file's coordinates scaled per axis, then turned by
/// `degrees` about `axis` (right-handed), then moved by `translate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub scale: [f64; 3],
    pub axis: [f64; 3],
    pub degrees: f64,
    pub translate: [f64; 3],
}

impl Placement {
    /// The point `p` of the file in scene coordinates.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let s = [p[0] * self.scale[0], p[1] * self.scale[1], p[2] * self.scale[2]];
        let len = self.axis.iter().map(|c| c * c).sum::<f64>().sqrt();
        let r = if self.degrees == 0.0 || len == 0.0 {
            s
        } else {
            // Rodrigues' rotation formula: v cos t + (k x v) sin t + k (k . v)(1 - cos t).
            let k = self.axis.map(|c| c / len);
            let (sin, cos) = self.degrees.to_radians().sin_cos();
            let kv = dot(k, s);
            let kxv = cross(k, s);
            std::array::from_fn(|a| s[a] * cos + kxv[a] * sin + k[a] * kv * (1.0 - cos))
        };
        std::array::from_fn(|a| r[a] + self.translate[a])
    }

    /// Every triangle placed.
    pub fn apply_all(&self, triangles: &[Triangle]) -> Vec<Triangle> {
        triangles.iter().map(|t| t.map(|p| self.apply(p))).collect()
    }
}

/// A mesh file's triangles in its own coordinates, shared by the copies of a scene, with the
/// indexes built of them so far: the scene's checks, its walls and its fluid's cut each need the
/// placed surface indexed for the same reach, and building the index of a large mesh costs more
/// than any one of them.
#[derive(Clone, Default)]
pub struct MeshSurface {
    triangles: Option<Arc<Vec<Triangle>>>,
    indexes: Arc<Mutex<Vec<(IndexKey, Arc<SurfaceIndex>)>>>,
}

/// What an index depends on besides the triangles: the placement and the reach, bit for bit.
type IndexKey = [u64; 11];

/// How many indexes a surface keeps: a run asks for one or two reaches (its scene's and, with
/// `--particles`, the file's), a resolution study one per resolution.
const KEPT_INDEXES: usize = 4;

impl MeshSurface {
    pub fn new(triangles: Vec<Triangle>) -> Self {
        MeshSurface { triangles: Some(Arc::new(triangles)), indexes: Arc::default() }
    }

    /// The file's triangles; `None` before the file is read.
    pub fn triangles(&self) -> Option<&[Triangle]> {
        self.triangles.as_deref().map(Vec::as_slice)
    }

    /// The surface placed by `placement` and indexed for distances below `reach`: built once,
    /// then shared by every copy of the scene that asks for the same placement and reach.
    pub fn index(&self, placement: &Placement, reach: f64) -> Arc<SurfaceIndex> {
        let mut key = [0u64; 11];
        let numbers = placement.scale.iter().chain(&placement.axis).chain([&placement.degrees]).chain(&placement.translate).chain([&reach]);
        for (k, x) in key.iter_mut().zip(numbers) {
            *k = x.to_bits();
        }
        // A poisoned lock only means another thread panicked while building: start afresh.
        let mut kept = self.indexes.lock().unwrap_or_else(|e| {
            let mut kept = e.into_inner();
            kept.clear();
            kept
        });
        if let Some((_, index)) = kept.iter().find(|(k, _)| *k == key) {
            return index.clone();
        }
        let placed = self.triangles().map(|t| placement.apply_all(t)).unwrap_or_default();
        let index = Arc::new(SurfaceIndex::new(placed, reach));
        if kept.len() == KEPT_INDEXES {
            kept.remove(0);
        }
        kept.push((key, index.clone()));
        index
    }
}

impl std::fmt::Debug for MeshSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.triangles {
            Some(t) => write!(f, "MeshSurface({} triangles)", t.len()),
            None => write!(f, "MeshSurface(not read)"),
        }
    }
}

/// Two surfaces are equal when their triangles are; the indexes are a cache.
impl PartialEq for MeshSurface {
    fn eq(&self, other: &Self) -> bool {
        match (&self.triangles, &other.triangles) {
            (Some(a), Some(b)) => Arc::ptr_eq(a, b) || a == b,
            (None, None) => true,
            _ => false,
        }
    }
}

/// The smallest box around the triangles.
pub fn bounds(triangles: &[Triangle]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in triangles.iter().flatten() {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// The distance from `p` to the box `lo..hi` (0 inside it).
fn box_distance(p: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
    (0..3).map(|a| (lo[a] - p[a]).max(p[a] - hi[a]).max(0.0).powi(2)).sum::<f64>().sqrt()
}

/// A triangle's area.
pub fn area(t: &Triangle) -> f64 {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    0.5 * dot(n, n).sqrt()
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The squared distance from `p` to the triangle `t` (its closest point found by the region
/// of the triangle's plane that `p` projects into: a corner, an edge or the inside; Ericson,
/// Real-Time Collision Detection, 2005, Sec. 5.1.5).
pub fn distance_squared(p: [f64; 3], t: &Triangle) -> f64 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    let to = |q: [f64; 3]| {
        let d = sub(p, q);
        dot(d, d)
    };
    let along = |o: [f64; 3], e: [f64; 3], s: f64| [o[0] + s * e[0], o[1] + s * e[1], o[2] + s * e[2]];
    if d1 <= 0.0 && d2 <= 0.0 {
        return to(a);
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return to(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return to(along(a, ab, d1 / (d1 - d3)));
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return to(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return to(along(a, ac, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return to(along(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = va + vb + vc;
    if denom == 0.0 {
        // A triangle of no area: the nearest of its edges' points.
        let seg = |o: [f64; 3], e: [f64; 3]| {
            let l = dot(e, e);
            let s = if l > 0.0 { (dot(sub(p, o), e) / l).clamp(0.0, 1.0) } else { 0.0 };
            to(along(o, e, s))
        };
        return seg(a, ab).min(seg(a, ac)).min(seg(b, sub(c, b)));
    }
    let (v, w) = (vb / denom, vc / denom);
    to([a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w, a[2] + ab[2] * v + ac[2] * w])
}

/// A placed closed surface indexed for two questions about a point: which side of the surface
/// it lies on, and how far from the surface it is when that is less than `reach`.
pub struct SurfaceIndex {
    triangles: Vec<Triangle>,
    lo: [f64; 3],
    hi: [f64; 3],
    /// Rays are cast along +x from a point moved by this much in y and z, so that no ray runs
    /// exactly through an edge or a corner of a mesh whose corners lie on round coordinates.
    nudge: [f64; 2],
    /// The triangles over each cell of a grid across the box's y-z extent (for the rays).
    columns: Vec<Vec<u32>>,
    column_count: [usize; 2],
    column_size: [f64; 2],
    /// The triangles within `reach` of some point of each cube of side `reach` (for the
    /// distances), each with a lower bound of its distance from the cube's centre, nearest
    /// first.
    cells: HashMap<[i64; 3], Vec<(f64, u32)>>,
    reach: f64,
}

impl SurfaceIndex {
    /// Indexes `triangles` (placed; closed) for distances below `reach` (> 0).
    pub fn new(triangles: Vec<Triangle>, reach: f64) -> Self {
        let (lo, hi) = bounds(&triangles);
        let diagonal = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>().sqrt().max(reach);
        // Irrational fractions of a tiny length: a ray passes an edge only by an accident of
        // rounding, not because the mesh and the lattice share round numbers.
        let nudge = [diagonal * 1e-9 * 0.618_033_988_749_894_8, diagonal * 1e-9 * 0.414_213_562_373_095_1];
        let side = ((triangles.len() as f64).sqrt().ceil() as usize).clamp(1, 1024);
        let column_count = [side, side];
        let column_size = [((hi[1] - lo[1]) / side as f64).max(f64::MIN_POSITIVE), ((hi[2] - lo[2]) / side as f64).max(f64::MIN_POSITIVE)];
        let mut columns = vec![Vec::new(); side * side];
        let column_of = |y: f64, z: f64| -> [usize; 2] {
            [
                (((y - lo[1]) / column_size[0]).floor().max(0.0) as usize).min(side - 1),
                (((z - lo[2]) / column_size[1]).floor().max(0.0) as usize).min(side - 1),
            ]
        };
        for (i, t) in triangles.iter().enumerate() {
            let (tlo, thi) = bounds(std::slice::from_ref(t));
            let a = column_of(tlo[1] - nudge[0], tlo[2] - nudge[1]);
            let b = column_of(thi[1] + nudge[0], thi[2] + nudge[1]);
            for k in a[1]..=b[1] {
                for j in a[0]..=b[0] {
                    columns[k * side + j].push(i as u32);
                }
            }
        }
        let mut cells: HashMap<[i64; 3], Vec<(f64, u32)>> = HashMap::new();
        // A point of a cube lies within half its diagonal of the centre: a triangle within
        // `reach` of any point of it lies within reach + that of the centre.
        let margin = reach + 0.5 * 3f64.sqrt() * reach;
        for (i, t) in triangles.iter().enumerate() {
            let (tlo, thi) = bounds(std::slice::from_ref(t));
            // A triangle much smaller than a cube is placed by its box, whose distance is a
            // lower bound of its own and cheaper; a large one (a tank's face) by itself, so
            // that it lands only in the cubes along it.
            let large = (0..3).any(|a| thi[a] - tlo[a] > 2.0 * reach);
            let first: [i64; 3] = std::array::from_fn(|a| ((tlo[a] - reach) / reach).floor() as i64);
            let last: [i64; 3] = std::array::from_fn(|a| ((thi[a] + reach) / reach).floor() as i64);
            for z in first[2]..=last[2] {
                for y in first[1]..=last[1] {
                    for x in first[0]..=last[0] {
                        let centre = [(x as f64 + 0.5) * reach, (y as f64 + 0.5) * reach, (z as f64 + 0.5) * reach];
                        let near = if large { distance_squared(centre, t).sqrt() } else { box_distance(centre, tlo, thi) };
                        if near <= margin {
                            cells.entry([x, y, z]).or_default().push((near, i as u32));
                        }
                    }
                }
            }
        }
        for near in cells.values_mut() {
            near.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        }
        SurfaceIndex { triangles, lo, hi, nudge, columns, column_count, column_size, cells, reach }
    }

    /// The cube of side `reach` that holds `p`.
    fn cell_of(&self, p: [f64; 3]) -> [i64; 3] {
        p.map(|c| (c / self.reach).floor() as i64)
    }

    /// Whether `p` lies inside the closed surface: the count of its crossings along a ray
    /// towards +x is odd.
    pub fn inside(&self, p: [f64; 3]) -> bool {
        let (y, z) = (p[1] + self.nudge[0], p[2] + self.nudge[1]);
        if p[0] > self.hi[0] || y < self.lo[1] || y > self.hi[1] || z < self.lo[2] || z > self.hi[2] {
            return false;
        }
        let j = (((y - self.lo[1]) / self.column_size[0]).floor().max(0.0) as usize).min(self.column_count[0] - 1);
        let k = (((z - self.lo[2]) / self.column_size[1]).floor().max(0.0) as usize).min(self.column_count[1] - 1);
        let mut crossings = 0u32;
        for &i in &self.columns[k * self.column_count[0] + j] {
            let [a, b, c] = self.triangles[i as usize];
            // Barycentric coordinates of (y, z) in the triangle's projection on the y-z plane.
            let area = (b[1] - a[1]) * (c[2] - a[2]) - (c[1] - a[1]) * (b[2] - a[2]);
            if area == 0.0 {
                continue; // seen edge-on: the ray crosses its neighbours instead
            }
            let u = ((b[1] - y) * (c[2] - z) - (c[1] - y) * (b[2] - z)) / area;
            let v = ((c[1] - y) * (a[2] - z) - (a[1] - y) * (c[2] - z)) / area;
            let w = 1.0 - u - v;
            if u < 0.0 || v < 0.0 || w < 0.0 {
                continue;
            }
            if u * a[0] + v * b[0] + w * c[0] > p[0] {
                crossings += 1;
            }
        }
        crossings % 2 == 1
    }

    /// The distance from `p` to the surface, where it is below `reach`.
    pub fn distance_within_reach(&self, p: [f64; 3]) -> Option<f64> {
        let cell = self.cell_of(p);
        let near = self.cells.get(&cell)?;
        // A triangle is at least its distance from the centre (of which the list holds a lower
        // bound) less p's from the centre away from p: past the first that cannot come nearer
        // than the nearest found, none can.
        let centre = cell.map(|c| (c as f64 + 0.5) * self.reach);
        let off = sub(p, centre);
        let off = dot(off, off).sqrt();
        let mut best = f64::INFINITY;
        for &(from_centre, i) in near {
            if from_centre - off >= best {
                break;
            }
            best = best.min(distance_squared(p, &self.triangles[i as usize]).sqrt());
        }
        (best < self.reach).then_some(best)
    }

    /// The points `origin + (i + 1/2) spacing` (per axis) of the lattice that lie on the
    /// `inside` side of the surface (or the outside, when false) and nearer to it than
    /// `depth` (at most the reach), ordered with x running fastest.
    pub fn band_points(&self, origin: [f64; 3], spacing: f64, depth: f64, inside: bool) -> Vec<[f64; 3]> {
        use rayon::prelude::*;
        let cells: Vec<&[i64; 3]> = self.cells.keys().collect();
        // Each cube's points are found on their own (in parallel), then put in order.
        let mut found: Vec<[i64; 3]> = cells.par_iter().flat_map_iter(|&cell| self.cube_band_points(cell, origin, spacing, depth, inside)).collect();
        found.sort_unstable_by_key(|c| [c[2], c[1], c[0]]);
        let point = |a: usize, i: i64| origin[a] + (i as f64 + 0.5) * spacing;
        found.into_iter().map(|[i, j, k]| [point(0, i), point(1, j), point(2, k)]).collect()
    }

    /// Whether [`SurfaceIndex::band_points`] would find any point (it stops at the first).
    pub fn has_band_point(&self, origin: [f64; 3], spacing: f64, depth: f64, inside: bool) -> bool {
        self.cells.keys().any(|cell| !self.cube_band_points(cell, origin, spacing, depth, inside).is_empty())
    }

    /// The lattice indices of [`SurfaceIndex::band_points`] whose points fall in one cube.
    fn cube_band_points(&self, cell: &[i64; 3], origin: [f64; 3], spacing: f64, depth: f64, inside: bool) -> Vec<[i64; 3]> {
        let point = |a: usize, i: i64| origin[a] + (i as f64 + 0.5) * spacing;
        let mut found = Vec::new();
        // The lattice indices whose points fall in this cube, one more each way for the
        // rounding, each then kept by the cube its point falls in.
        let range = |a: usize| {
            let lo = ((cell[a] as f64 * self.reach - origin[a]) / spacing - 0.5).floor() as i64 - 1;
            let hi = (((cell[a] + 1) as f64 * self.reach - origin[a]) / spacing - 0.5).ceil() as i64 + 1;
            lo..=hi
        };
        for k in range(2) {
            for j in range(1) {
                for i in range(0) {
                    let p = [point(0, i), point(1, j), point(2, k)];
                    if self.cell_of(p) != *cell {
                        continue;
                    }
                    if self.distance_within_reach(p).is_some_and(|d| d < depth) && self.inside(p) == inside {
                        found.push([i, j, k]);
                    }
                }
            }
        }
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUBE_OBJ: &str = "# a unit cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
        f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";

    fn cube() -> Vec<Triangle> {
        parse_mesh(CUBE_OBJ.as_bytes(), "obj").unwrap()
    }

    /// A sphere of radius 1 about the origin, by subdividing an octahedron.
    fn sphere(levels: u32) -> Vec<Triangle> {
        let norm = |p: [f64; 3]| {
            let l = dot(p, p).sqrt();
            p.map(|c| c / l)
        };
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        let neg = |p: [f64; 3]| p.map(|c| -c);
        let mut tris: Vec<Triangle> = Vec::new();
        for sx in [x, neg(x)] {
            for sy in [y, neg(y)] {
                for sz in [z, neg(z)] {
                    tris.push([sx, sy, sz]);
                }
            }
        }
        for _ in 0..levels {
            tris = tris
                .iter()
                .flat_map(|&[a, b, c]| {
                    let mid = |p: [f64; 3], q: [f64; 3]| norm(std::array::from_fn(|k| 0.5 * (p[k] + q[k])));
                    let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
                    [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
                })
                .collect();
        }
        tris
    }

    #[test]
    fn an_index_is_built_once_per_placement_and_reach_and_shared_by_copies() {
        let surface = MeshSurface::new(cube());
        let copy = surface.clone();
        let at = Placement { scale: [2.0; 3], axis: [0.0, 1.0, 0.0], degrees: 30.0, translate: [1.0, 0.0, 0.0] };
        let first = surface.index(&at, 0.25);
        assert!(Arc::ptr_eq(&first, &copy.index(&at, 0.25)), "a copy of the scene builds it again");
        // Another reach or placement is another index, placed as asked.
        assert!(!Arc::ptr_eq(&first, &surface.index(&at, 0.125)));
        let moved = Placement { translate: [3.0, 0.0, 0.0], ..at };
        let other = surface.index(&moved, 0.25);
        assert!(!Arc::ptr_eq(&first, &other));
        assert!(other.inside(moved.apply([0.5, 0.5, 0.5])) && !other.inside(at.apply([0.5, 0.5, 0.5])));
        // Only the last few are kept; one dropped is built again, the same.
        for k in 0..KEPT_INDEXES {
            surface.index(&at, 1.0 + k as f64);
        }
        let again = surface.index(&at, 0.25);
        assert!(!Arc::ptr_eq(&first, &again));
        assert_eq!(again.band_points([0.0; 3], 0.25, 0.5, true), first.band_points([0.0; 3], 0.25, 0.5, true));
        // The cache is not part of what the surface is.
        assert_eq!(MeshSurface::new(cube()), surface);
    }

    #[test]
    fn obj_faces_are_cut_into_fans_and_indices_resolved() {
        let t = cube();
        assert_eq!(t.len(), 12);
        assert_eq!(open_edges(&t), None);
        // Negative indices count back from the last vertex read; v/vt/vn forms read the v.
        let rel = parse_mesh(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3/1/1 -2//2 -1\n", "OBJ").unwrap();
        assert_eq!(rel, vec![[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]);
        let (count, at) = open_edges(&rel).unwrap();
        assert_eq!(count, 3);
        assert!(at.iter().all(|c| (0.0..=1.0).contains(c)));
    }

    #[test]
    fn bad_files_name_the_line_and_what_is_wrong() {
        let e = |text: &str| parse_mesh(text.as_bytes(), "obj").unwrap_err();
        assert!(e("v 0 0\n").contains("line 1"), "{}", e("v 0 0\n"));
        assert!(e("v 0 0 nan\n").contains("'nan' is not a finite number"));
        assert!(e("v 0 0 0\nv 1 0 0\nf 1 2\n").contains("line 3: a face needs at least three vertices"));
        assert!(e("v 0 0 0\nf 1 2 3\n").contains("vertex index 2 is past the last vertex (1 in the file)"));
        assert!(e("v 0 0 0\nf 0 1 1\n").contains("index 0"));
        assert!(e("v 0 0 0\nf -2 1 1\n").contains("before the first vertex"));
        assert!(e("# nothing\n").contains("no triangle"));
        assert!(parse_mesh(b"", "ply").unwrap_err().contains("'ply'"));
        assert!(parse_mesh(b"not an stl", "stl").unwrap_err().contains("neither a binary STL"));
    }

    #[test]
    fn stl_binary_and_ascii_read_the_same_triangles() {
        let t = cube();
        let mut binary = vec![0u8; 80];
        binary[..5].copy_from_slice(b"solid"); // as some writers do
        binary.extend((t.len() as u32).to_le_bytes());
        let mut ascii = String::from("solid cube\n");
        for tri in &t {
            binary.extend([0u8; 12]);
            ascii.push_str(" facet normal 0 0 0\n  outer loop\n");
            for p in tri {
                binary.extend(p.iter().flat_map(|&c| (c as f32).to_le_bytes()));
                ascii.push_str(&format!("   vertex {} {} {}\n", p[0], p[1], p[2]));
            }
            binary.extend([0u8; 2]);
            ascii.push_str("  endloop\n endfacet\n");
        }
        ascii.push_str("endsolid cube\n");
        assert_eq!(parse_mesh(&binary, "stl").unwrap(), t);
        assert_eq!(parse_mesh(ascii.as_bytes(), "STL").unwrap(), t);
        assert!(parse_mesh(b"solid x\nvertex 0 0 0\nvertex 1 0 0\n", "stl").unwrap_err().contains("not three for each facet"));
    }

    #[test]
    fn placement_scales_then_turns_then_moves() {
        let p = Placement { scale: [2.0, 1.0, 1.0], axis: [0.0, 0.0, 1.0], degrees: 90.0, translate: [10.0, 0.0, 0.0] };
        let q = p.apply([1.0, 0.0, 0.0]);
        // (1,0,0) -> (2,0,0) -> turned a quarter about z: (0,2,0) -> moved: (10,2,0).
        assert!((q[0] - 10.0).abs() < 1e-12 && (q[1] - 2.0).abs() < 1e-12 && q[2].abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn distances_match_the_geometry() {
        let t: Triangle = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let d = |p: [f64; 3]| distance_squared(p, &t).sqrt();
        assert!((d([0.2, 0.2, 0.5]) - 0.5).abs() < 1e-12); // over the inside
        assert!((d([-1.0, -1.0, 0.0]) - 2f64.sqrt()).abs() < 1e-12); // nearest a corner
        assert!((d([0.5, -2.0, 0.0]) - 2.0).abs() < 1e-12); // nearest an edge
        assert!((d([1.0, 1.0, 0.0]) - 0.5f64.sqrt()).abs() < 1e-12); // the slanted edge
        let flat: Triangle = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert!((distance_squared([1.5, 1.0, 0.0], &flat) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn inside_holds_for_points_of_a_sphere_and_a_cube_on_round_coordinates() {
        let s = SurfaceIndex::new(sphere(4), 0.1);
        for (p, expected) in [([0.0, 0.0, 0.0], true), ([0.9, 0.0, 0.0], true), ([0.0, -0.9, 0.1], true), ([1.1, 0.0, 0.0], false), ([0.8, 0.8, 0.0], false)] {
            assert_eq!(s.inside(p), expected, "{p:?}");
        }
        // The cube's edges and corners lie on the rays of a lattice at round coordinates.
        let c = SurfaceIndex::new(cube(), 0.25);
        // (Points on a face are left out: either answer is right there.)
        for i in (-1..=9).filter(|&i| i != 0 && i != 8) {
            for j in (-1..=9).filter(|&j| j != 0 && j != 8) {
                let p = [0.5, i as f64 * 0.125, j as f64 * 0.125];
                let expected = (1..8).contains(&i) && (1..8).contains(&j);
                assert_eq!(c.inside(p), expected, "{p:?}");
            }
        }
    }

    #[test]
    fn a_cube_is_lined_with_whole_layers_on_either_side() {
        // Unit cube, lattice of 0.1 from the origin: the faces lie half-way between points.
        let c = SurfaceIndex::new(cube(), 0.2);
        let solid = c.band_points([0.0; 3], 0.1, 0.2, true);
        // Two layers inside: 10^3 points minus the 6^3 core.
        assert_eq!(solid.len(), 1000 - 216);
        assert!(solid.iter().all(|p| p.iter().all(|&x| x > 0.0 && x < 1.0)));
        let tank = c.band_points([0.0; 3], 0.1, 0.2, false);
        // Two layers outside: the 14^3 box less the cube, less the 8 x 3 corner points and
        // the 12 x 10 edge points farther than 0.2 from it (the rounded band of a distance).
        let by_distance = |p: &[f64; 3]| (0..3).map(|a| (0.0 - p[a]).max(p[a] - 1.0).max(0.0).powi(2)).sum::<f64>().sqrt() < 0.2;
        let mut expected = 0;
        for k in -2..12 {
            for j in -2..12 {
                for i in -2..12 {
                    let p = [(i as f64 + 0.5) * 0.1, (j as f64 + 0.5) * 0.1, (k as f64 + 0.5) * 0.1];
                    if !(0..10).contains(&i) || !(0..10).contains(&j) || !(0..10).contains(&k) {
                        expected += by_distance(&p) as usize;
                    }
                }
            }
        }
        assert_eq!(tank.len(), expected);
        // Ordered with x fastest, no point twice.
        let key = |p: &[f64; 3]| [p[2], p[1], p[0]];
        assert!(tank.windows(2).all(|w| key(&w[0]) < key(&w[1])));
    }

    #[test]
    fn a_sphere_band_holds_the_shell_between_the_two_radii() {
        let s = SurfaceIndex::new(sphere(5), 0.3);
        let points = s.band_points([-2.0; 3], 0.05, 0.15, true);
        // Every point inside, within 0.15 of the surface (up to the mesh's flattening).
        for p in &points {
            let r = dot(*p, *p).sqrt();
            assert!(r < 1.0 && r > 0.84, "{p:?} at r = {r}");
        }
        // The shell's volume over a point's cell, within a few per cent.
        let volume = 4.0 / 3.0 * std::f64::consts::PI * (1.0f64 - 0.85f64.powi(3));
        let expected = volume / 0.05f64.powi(3);
        assert!((points.len() as f64 / expected - 1.0).abs() < 0.05, "{} points, expected about {expected}", points.len());
    }
}
