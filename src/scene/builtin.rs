//! Built-in scenes: so that every command runs with no files, and so that the hard cases of
//! multi-fragment rendering (exact depth ties, nested surfaces, high depth complexity) are
//! one short name away.
//!
//! Every built-in is deterministic and bit-identical on every platform: random numbers come
//! from a fixed SplitMix64 (not `rand`'s generators, whose streams may change between
//! versions), and angles go through [`sin_cos`], which uses only IEEE-exact operations
//! (not the platform's libm, whose last bit varies). A case file that names a built-in
//! therefore replays exactly anywhere.

use std::ops::Range;

use fragrace_emu::geometry::Mesh;
use glam::{DVec3, Vec3};

use super::obj::parse_obj_bytes;
use super::SceneError;

/// The names of the built-in scenes.
pub const NAMES: &[&str] = &[
    "cubes",
    "coplanar-stack",
    "spheres",
    "hairball",
    "interpenetrating",
    "bunny",
    "teapot",
    "object-grid",
    "random-triangles",
];

/// How parameters are written: `name:param:param`.
pub const USAGE: &str = "cubes | coplanar-stack[:N] | spheres | hairball | interpenetrating | bunny | teapot | random-triangles[:SEED[:N]] | object-grid[:N]";

/// Number of quads of `coplanar-stack` without a parameter.
pub const COPLANAR_STACK_DEFAULT: usize = 8;
/// Seed and triangle count of `random-triangles` without parameters.
pub const RANDOM_TRIANGLES_DEFAULT: (u64, usize) = (0, 1000);
/// Number of closed tubes in `hairball`.
pub const HAIRBALL_CURVES: usize = 400;
/// Segments per hairball tube (each segment is 6 triangles).
pub const HAIRBALL_SEGMENTS: usize = 48;
/// Hairball tube radius, before normalisation (the ball is about 1.2 across): a tube is
/// a few pixels wide in a 512x512 view, thin but not sub-pixel.
pub const HAIRBALL_TUBE_RADIUS: f64 = 0.01;

/// The Stanford bunny (3,674 triangles), as shipped in `assets/`.
pub const BUNNY_OBJ_GZ: &[u8] = include_bytes!("../../assets/bunny.obj.gz");
/// The Utah teapot (992 triangles), as shipped in `assets/`.
pub const TEAPOT_OBJ_GZ: &[u8] = include_bytes!("../../assets/teapot.obj.gz");

/// Spheres per side of `object-grid` without a parameter (27 objects).
pub const OBJECT_GRID_DEFAULT: u32 = 3;

/// Upper bound on parameterised sizes, so that a typo in a case file cannot ask for
/// terabytes.
const MAX_PARAM_TRIANGLES: usize = 1 << 24;

/// The mesh of a built-in scene by name and its objects (ranges of its triangles; empty: one
/// object), not normalised. `object-grid` is made of objects; the other built-ins are one.
pub fn mesh_and_objects(name: &str) -> Result<(Mesh, Vec<Range<u32>>), SceneError> {
    let mut parts = name.split(':');
    if parts.next() != Some("object-grid") {
        return Ok((mesh(name)?, Vec::new()));
    }
    const U: &str = "object-grid[:N] with 1 <= N <= 64 spheres per side";
    let bad = || SceneError::BuiltinParams {
        name: name.to_owned(),
        usage: U,
    };
    let params: Vec<&str> = parts.collect();
    let n: u32 = match params[..] {
        [] => OBJECT_GRID_DEFAULT,
        [n] => n.parse().map_err(|_| bad())?,
        _ => return Err(bad()),
    };
    if n == 0 || n > 64 {
        return Err(bad());
    }
    Ok(object_grid(n))
}

/// The mesh of a built-in scene by name (`name` or `name:params`), not normalised.
pub fn mesh(name: &str) -> Result<Mesh, SceneError> {
    let mut parts = name.split(':');
    let base = parts.next().unwrap_or_default();
    let params: Vec<&str> = parts.collect();
    let bad = |usage| SceneError::BuiltinParams {
        name: name.to_owned(),
        usage,
    };
    let no_params = |mesh: fn() -> Mesh| {
        if params.is_empty() {
            Ok(mesh())
        } else {
            Err(bad(USAGE))
        }
    };
    match base {
        "cubes" => no_params(cubes),
        "spheres" => no_params(spheres),
        "hairball" => no_params(hairball),
        "interpenetrating" => no_params(interpenetrating),
        "bunny" | "teapot" if !params.is_empty() => Err(bad(USAGE)),
        "bunny" => parse_obj_bytes(BUNNY_OBJ_GZ),
        "teapot" => parse_obj_bytes(TEAPOT_OBJ_GZ),
        "coplanar-stack" => {
            const U: &str = "coplanar-stack[:N] with 1 <= N <= 8388608";
            let n = match params[..] {
                [] => COPLANAR_STACK_DEFAULT,
                [n] => n.parse().map_err(|_| bad(U))?,
                _ => return Err(bad(U)),
            };
            if n == 0 || 2 * n > MAX_PARAM_TRIANGLES {
                return Err(bad(U));
            }
            Ok(coplanar_stack(n))
        }
        "object-grid" => mesh_and_objects(name).map(|(m, _)| m),
        "random-triangles" => {
            const U: &str = "random-triangles[:SEED[:N]] with SEED a u64 and 1 <= N <= 16777216";
            let (mut seed, mut n) = RANDOM_TRIANGLES_DEFAULT;
            match params[..] {
                [] => {}
                [s] => seed = s.parse().map_err(|_| bad(U))?,
                [s, c] => {
                    seed = s.parse().map_err(|_| bad(U))?;
                    n = c.parse().map_err(|_| bad(U))?;
                }
                _ => return Err(bad(U)),
            }
            if n == 0 || n > MAX_PARAM_TRIANGLES {
                return Err(bad(U));
            }
            Ok(random_triangles(seed, n))
        }
        _ => Err(SceneError::UnknownBuiltin {
            name: name.to_owned(),
        }),
    }
}

/// Which diagonal splits a box's quads into triangles.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Diagonal {
    /// Corners 0 and 2 of each quad.
    First,
    /// Corners 1 and 3.
    Second,
}

/// Appends an axis-aligned box (8 vertices, 12 triangles, counter-clockwise seen from
/// outside, so back-face culling and `front_facing` behave).
fn push_box(mesh: &mut Mesh, lo: Vec3, hi: Vec3) {
    push_box_split(mesh, lo, hi, Diagonal::First);
}

/// [`push_box`] with the quads split along `diagonal`.
fn push_box_split(mesh: &mut Mesh, lo: Vec3, hi: Vec3, diagonal: Diagonal) {
    let base = mesh.positions.len() as u32;
    for i in 0..8 {
        let pick = |bit: u32, l: f32, h: f32| if i & bit != 0 { h } else { l };
        mesh.positions.push(Vec3::new(
            pick(1, lo.x, hi.x),
            pick(2, lo.y, hi.y),
            pick(4, lo.z, hi.z),
        ));
    }
    // Corner i has x = bit 0, y = bit 1, z = bit 2; quads are CCW from outside.
    const QUADS: [[u32; 4]; 6] = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    for [a, b, c, d] in QUADS {
        let tris = match diagonal {
            Diagonal::First => [[a, b, c], [a, c, d]],
            Diagonal::Second => [[a, b, d], [b, c, d]],
        };
        for t in tris {
            mesh.indices.push(t.map(|i| i + base));
        }
    }
}

/// `interpenetrating`: z-fighting surfaces, the case of the z-thickness paper's Figure 3
/// ("two superimposed cubes"). Two boxes on the same six planes, their quads split along
/// opposite diagonals, so that their fragments tie exactly or differ by a rounding step;
/// and two spheres of one centre and radius tessellated differently (16 x 32 and 15 x 29
/// segments), whose surfaces cross each other everywhere with depth gaps up to the
/// tessellation's sagitta (about 0.6 % of the radius). 1,796 triangles. The order of
/// such fragments is decided by rounding and arrival, the speckle of z-fighting; a
/// z-thickness wider than the gaps merges them.
pub fn interpenetrating() -> Mesh {
    let mut mesh = Mesh::default();
    let (lo, hi) = (Vec3::splat(-0.5), Vec3::splat(0.5));
    push_box_split(&mut mesh, lo, hi, Diagonal::First);
    push_box_split(&mut mesh, lo, hi, Diagonal::Second);
    mesh.normals = None;
    let mut spheres = uv_sphere(Vec3::ZERO, 0.7, 16, 32);
    spheres.append(&uv_sphere(Vec3::ZERO, 0.7, 15, 29));
    spheres.normals = None;
    mesh.append(&spheres);
    mesh
}

/// `cubes`: three overlapping unit cubes whose faces are *exactly* coplanar in places:
/// A = `[-1,0]x[-0.5,0.5]x[-0.5,0.5]` and B = `[-0.5,0.5]^3` share their four y and z face
/// planes; C = `[0,1]x[0,1]x[-0.5,0.5]` shares the z planes, and its x = 0 face lies in
/// the plane of A's x = 0 face. Coplanar overlapping faces produce fragments of equal depth
/// at the same pixel: the case where sorting needs a tie-break and races are hardest to
/// see. All coordinates are dyadic and the normalisation scale is 1/2, so the planes stay
/// exactly equal after normalisation.
pub fn cubes() -> Mesh {
    let mut mesh = Mesh::default();
    push_box(
        &mut mesh,
        Vec3::new(-1.0, -0.5, -0.5),
        Vec3::new(0.0, 0.5, 0.5),
    );
    push_box(
        &mut mesh,
        Vec3::new(-0.5, -0.5, -0.5),
        Vec3::new(0.5, 0.5, 0.5),
    );
    push_box(
        &mut mesh,
        Vec3::new(0.0, 0.0, -0.5),
        Vec3::new(1.0, 1.0, 0.5),
    );
    mesh
}

/// `coplanar-stack`: `n` identical quads (2 triangles each, each quad with its own four
/// vertices at the same positions) in the plane z = 0, facing the default camera: every
/// covered pixel gets `n` fragments of exactly equal depth, so only the primitive id orders
/// them, the worst case for an algorithm that sorts by depth alone.
pub fn coplanar_stack(n: usize) -> Mesh {
    let mut mesh = Mesh::default();
    for q in 0..n {
        let base = 4 * q as u32;
        mesh.positions.extend([
            Vec3::new(-0.5, -0.5, 0.0),
            Vec3::new(0.5, -0.5, 0.0),
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::new(-0.5, 0.5, 0.0),
        ]);
        mesh.indices.push([base, base + 1, base + 2]);
        mesh.indices.push([base, base + 2, base + 3]);
    }
    mesh
}

/// A closed UV sphere: shared pole vertices and a shared seam, so every edge belongs to
/// exactly two triangles (a watertight surface: every pixel inside its silhouette gets one
/// entering and one leaving fragment). CCW from outside, with exact outward normals.
fn uv_sphere(centre: Vec3, radius: f32, stacks: u32, slices: u32) -> Mesh {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut push = |n: DVec3| {
        normals.push(n.as_vec3());
        positions.push(centre + (n * f64::from(radius)).as_vec3());
    };
    push(DVec3::Y);
    for i in 1..stacks {
        let (st, ct) = sin_cos(std::f64::consts::PI * f64::from(i) / f64::from(stacks));
        for j in 0..slices {
            let (sp, cp) = sin_cos(std::f64::consts::TAU * f64::from(j) / f64::from(slices));
            push(DVec3::new(st * sp, ct, st * cp));
        }
    }
    push(DVec3::NEG_Y);
    let south = positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * slices + j % slices;
    let mut indices = Vec::new();
    for j in 0..slices {
        indices.push([0, ring(1, j), ring(1, j + 1)]);
        for i in 1..stacks - 1 {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i + 1, j),
                ring(i + 1, j + 1),
                ring(i, j + 1),
            );
            indices.push([a, b, c]);
            indices.push([a, c, d]);
        }
        indices.push([south, ring(stacks - 1, j + 1), ring(stacks - 1, j)]);
    }
    Mesh {
        positions,
        normals: Some(normals),
        indices,
    }
}

/// `spheres`: three nested closed spheres (radii 1, 0.65, 0.3, centres slightly offset but
/// strictly inside each other), 6,624 triangles: six surfaces along a central ray, the
/// classic "transparent layers" case, with every layer a closed surface.
pub fn spheres() -> Mesh {
    let mut mesh = uv_sphere(Vec3::ZERO, 1.0, 24, 48);
    mesh.append(&uv_sphere(Vec3::new(0.125, 0.0625, 0.0), 0.65, 24, 48));
    mesh.append(&uv_sphere(Vec3::new(0.1875, 0.125, 0.0625), 0.3, 24, 48));
    mesh
}

/// A torus of `n` x `m` quads (two triangles each), radii 1 and 0.4 about the y axis: the
/// smallest closed surface whose triangles occlude each other in cycles across viewpoints
/// (the depth-presorted lists' case; not a named scene). Angles through [`sin_cos`], so it
/// is bit-identical everywhere.
pub fn torus(n: u32, m: u32) -> Mesh {
    let (big, small) = (1.0f64, 0.4f64);
    let mut positions = Vec::with_capacity(n as usize * m as usize);
    for i in 0..n {
        let (su, cu) = sin_cos(std::f64::consts::TAU * f64::from(i) / f64::from(n));
        for j in 0..m {
            let (sv, cv) = sin_cos(std::f64::consts::TAU * f64::from(j) / f64::from(m));
            let r = big + small * cv;
            positions.push(DVec3::new(r * cu, small * sv, r * su).as_vec3());
        }
    }
    let mut indices = Vec::with_capacity(2 * n as usize * m as usize);
    for i in 0..n {
        for j in 0..m {
            let a = i * m + j;
            let b = ((i + 1) % n) * m + j;
            let c = ((i + 1) % n) * m + (j + 1) % m;
            let d = i * m + (j + 1) % m;
            indices.push([a, b, c]);
            indices.push([a, c, d]);
        }
    }
    Mesh {
        positions,
        normals: None,
        indices,
    }
}

/// `object-grid[:N]`: `N x N x N` small closed spheres (radius 0.3, 8 stacks, 12 slices:
/// 168 triangles each) on a grid of spacing 1, each sphere one object (the depth-fighting
/// paper's geometry culling, section 3.3, needs a scene of many objects). Seen from the
/// default camera, the spheres of the front rows hide parts of those behind them: a
/// front-to-back peel finishes them in the first iterations and culls them for the rest.
pub fn object_grid(n: u32) -> (Mesh, Vec<Range<u32>>) {
    let mut mesh = Mesh::default();
    let mut objects = Vec::new();
    let half = (n as f32 - 1.0) / 2.0;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let c = Vec3::new(i as f32 - half, j as f32 - half, k as f32 - half);
                let start = mesh.indices.len() as u32;
                let sphere = uv_sphere(c, 0.3, 8, 12);
                if mesh.positions.is_empty() {
                    mesh = sphere;
                } else {
                    mesh.append(&sphere);
                }
                objects.push(start..mesh.indices.len() as u32);
            }
        }
    }
    (mesh, objects)
}

/// `hairball`: [`HAIRBALL_CURVES`] closed thin tubes (triangular prisms, radius
/// [`HAIRBALL_TUBE_RADIUS`], [`HAIRBALL_SEGMENTS`] segments each, 115,200 triangles) along random smooth loops that
/// concentrate towards the centre of a ball: the depth complexity at the centre of the
/// default view is over 50 (tested), the regime where per-pixel lists overflow and
/// k-buffers must drop fragments. Each tube is a closed, consistently oriented surface.
pub fn hairball() -> Mesh {
    let mut rng = SplitMix64::new(0x4a17_ba11);
    let mut mesh = Mesh::default();
    for _ in 0..HAIRBALL_CURVES {
        let curve = LoopCurve::random(&mut rng);
        push_tube(&mut mesh, &curve, HAIRBALL_SEGMENTS, HAIRBALL_TUBE_RADIUS);
    }
    mesh
}

/// A closed curve `p(t)`, `t` in `[0, 2 pi)`: per axis a sum of sines of frequencies 1, 2, 3
/// with random amplitudes and phases. Sums of random-phase sines pile up near 0, so the
/// loops are densest at the centre, which is what makes the depth complexity high there.
struct LoopCurve {
    /// `[axis][harmonic] = (amplitude, phase)`.
    terms: [[(f64, f64); 3]; 3],
}

impl LoopCurve {
    fn random(rng: &mut SplitMix64) -> Self {
        let mut terms = [[(0.0, 0.0); 3]; 3];
        for axis in &mut terms {
            for (k, term) in axis.iter_mut().enumerate() {
                let amplitude = [0.3, 0.15, 0.1][k] * rng.range(0.5, 1.0);
                *term = (amplitude, rng.range(0.0, std::f64::consts::TAU));
            }
        }
        LoopCurve { terms }
    }

    /// Position and (unnormalised) tangent at `t`.
    fn eval(&self, t: f64) -> (DVec3, DVec3) {
        let mut p = [0.0; 3];
        let mut d = [0.0; 3];
        for (axis, terms) in self.terms.iter().enumerate() {
            for (k, &(a, phase)) in terms.iter().enumerate() {
                let f = (k + 1) as f64;
                let (s, c) = sin_cos(f * t + phase);
                p[axis] += a * s;
                d[axis] += a * f * c;
            }
        }
        (DVec3::from_array(p), DVec3::from_array(d))
    }
}

/// Appends a closed triangular-prism tube along a loop: `segments` rings of 3 vertices and
/// 6 triangles per segment, CCW from outside. Ring frames are parallel-transported; where
/// the loop closes, the last ring joins the first with the cyclic vertex offset that twists
/// least (a transported frame does not come back to itself around a loop).
fn push_tube(mesh: &mut Mesh, curve: &LoopCurve, segments: usize, radius: f64) {
    const RING: [(f64, f64); 3] = [
        (1.0, 0.0),
        (-0.5, 0.866_025_403_784_438_6),
        (-0.5, -0.866_025_403_784_438_6),
    ];
    let base = mesh.positions.len() as u32;
    let mut normal = DVec3::ZERO;
    let mut tangent = DVec3::X;
    let mut first_frame = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
    for i in 0..segments {
        let (p, d) = curve.eval(std::f64::consts::TAU * i as f64 / segments as f64);
        if d.length_squared() > 1e-24 {
            tangent = d.normalize();
        }
        if i == 0 {
            // Any unit vector perpendicular to the tangent.
            let helper = if tangent.x.abs() < 0.9 {
                DVec3::X
            } else {
                DVec3::Y
            };
            normal = tangent.cross(helper).normalize();
        } else {
            let projected = normal - tangent * tangent.dot(normal);
            if projected.length_squared() > 1e-24 {
                normal = projected.normalize();
            }
        }
        let binormal = tangent.cross(normal);
        if i == 0 {
            first_frame = (tangent, normal, binormal);
        }
        for (c, s) in RING {
            mesh.positions
                .push((p + radius * (c * normal + s * binormal)).as_vec3());
        }
    }
    // Closing offset: the first ring's vertex that best matches the transported normal.
    let (t0, n0, b0) = first_frame;
    let back = normal - t0 * t0.dot(normal);
    let offset = (0..3)
        .max_by(|&a, &b| {
            let score = |k: usize| back.dot(RING[k].0 * n0 + RING[k].1 * b0);
            score(a).total_cmp(&score(b))
        })
        .unwrap_or(0);
    let vertex = |ring: usize, k: usize| {
        let (ring, k) = if ring == segments {
            (0, k + offset)
        } else {
            (ring, k)
        };
        base + (3 * ring + k % 3) as u32
    };
    for i in 0..segments {
        for k in 0..3 {
            let (a, b, c, d) = (
                vertex(i, k),
                vertex(i, k + 1),
                vertex(i + 1, k + 1),
                vertex(i + 1, k),
            );
            mesh.indices.push([a, b, c]);
            mesh.indices.push([a, c, d]);
        }
    }
}

/// Random triangles for fuzzing the rasterizer and the kernels: `n` triangles in `[-2, 2]^3`
/// of sizes from 1/128 to 1 (roughly log-uniform), deterministic in `seed`. To exercise the hard
/// cases on purpose, about 1 in 10 exactly repeats an earlier triangle's vertices (an exact
/// depth tie) and about 1 in 6 shares an edge with an earlier triangle (watertightness: a
/// pixel centre on the shared edge must be covered exactly once).
pub fn random_triangles(seed: u64, n: usize) -> Mesh {
    let mut rng = SplitMix64::new(seed);
    let mut mesh = Mesh::default();
    let point = |rng: &mut SplitMix64, centre: DVec3, size: f64| {
        let offset = DVec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        (centre + size * offset).as_vec3()
    };
    for i in 0..n {
        let kind = rng.unit();
        let earlier = mesh
            .indices
            .get(rng.below(i.max(1) as u64) as usize)
            .copied();
        let size = rng.range(0.5, 1.0) / f64::from(1u32 << rng.below(7));
        match earlier {
            Some(t) if kind < 0.1 => mesh.indices.push(t),
            Some([a, b, _]) if kind < 0.27 => {
                // Share edge (b, a), in the opposite direction as a neighbour would.
                let centre =
                    (mesh.positions[a as usize] + mesh.positions[b as usize]).as_dvec3() / 2.0;
                let p = point(&mut rng, centre, size);
                mesh.positions.push(p);
                mesh.indices.push([b, a, mesh.positions.len() as u32 - 1]);
            }
            _ => {
                let centre = DVec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                );
                let base = mesh.positions.len() as u32;
                for _ in 0..3 {
                    let p = point(&mut rng, centre, size);
                    mesh.positions.push(p);
                }
                mesh.indices.push([base, base + 1, base + 2]);
            }
        }
    }
    mesh
}

/// SplitMix64 (Steele, Lea and Flood 2014): tiny, fast, and its stream is fixed forever, so
/// seeded scenes never change under a dependency update.
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`, exactly representable (53 random bits).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform in `[0, n)` for n > 0 (the tiny modulo bias is irrelevant here).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

/// `(sin x, cos x)` from additions, multiplications and divisions only (each correctly
/// rounded by IEEE 754, unlike libm's `sin`), so the result is the same on every platform.
/// Reduced to `[-pi, pi]`, then Taylor series to 1e-16 or so.
pub fn sin_cos(x: f64) -> (f64, f64) {
    use std::f64::consts::TAU;
    let r = x - (x / TAU).round() * TAU;
    let r2 = r * r;
    let (mut sin, mut cos) = (0.0, 0.0);
    let (mut s_term, mut c_term) = (r, 1.0);
    for k in 1..=20 {
        sin += s_term;
        cos += c_term;
        let k = f64::from(k);
        s_term *= -r2 / ((2.0 * k) * (2.0 * k + 1.0));
        c_term *= -r2 / ((2.0 * k - 1.0) * (2.0 * k));
    }
    (sin, cos)
}
