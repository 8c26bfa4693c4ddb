//! Fuzz target logic, shared by the cargo-fuzz targets in `fuzz/` and the bounded smoke tests
//! of the normal test suite (`tests/fuzz_smoke.rs`), so that CI exercises every target.
//!
//! Each target is a plain function of the fuzzer's bytes (decoded with `arbitrary`) that
//! returns what it checked, or a [`Violation`] when it found a real bug; the libFuzzer
//! targets panic on a violation, which is how libFuzzer records a crash. Nothing here may
//! panic on any input: a panic is a bug of the code under test.
//!
//! - [`raster_watertight`]: arbitrary tilings (grids and fans of triangles that cover a region
//!   exactly, with arbitrary windings, sub-pixel positions, MSAA sample counts, tile sizes and
//!   near/far clipping) plus arbitrary other triangles through an arbitrary matrix (NaN,
//!   infinities, huge values), drawn through [`Device::draw`] with a counting kernel: within a
//!   tiling no sample is covered twice, no sample strictly inside the tiled region is missed,
//!   and no sample outside every triangle is covered; one triangle never covers a sample twice.
//! - [`kernel_oracle`]: an algorithm of the registry on a small random scene under the
//!   `scheduled` executor with an arbitrary schedule (`Policy::Bytes` of the remaining bytes),
//!   checked against the truth and against the algorithm's declared hazard class. One value of
//!   the selector byte picks the linked list with its planted bug instead
//!   ([`KernelOutcome::Planted`]), which the fuzzer is expected to find: a schedule under
//!   which the detector reports a torn record, or the in-pass reader follows the head to a
//!   node not written yet.
//! - [`obj_loader`]: [`parse_obj_bytes`] on arbitrary bytes; a mesh it accepts is valid and
//!   round-trips through OBJ text exactly.
//! - [`case_parser`]: [`case::parse`] on arbitrary bytes; a case it accepts re-serialises
//!   to a file that parses back equal; and an arbitrary case built from the bytes
//!   round-trips too.

use std::fmt;
use std::sync::OnceLock;

use arbitrary::{Arbitrary, Unstructured};
use fragrace_emu::{
    Buf, Device, Draw, ExecConfig, ExecMode, Fragment, FragmentKernel, Framebuffer, KernelInfo,
    Mesh, PassState, Policy, RasterState, SampleCount, ScheduleConfig,
};
use fragrace_kernels::abuffer::LinkedList;
use fragrace_kernels::{Algorithm, HazardClass, Params};
use glam::{Mat4, Vec3};

use crate::case::{self, Case, Observation, Size};
use crate::run::{self, RunSpec, SceneSpec};
use crate::scene::{parse_obj_bytes, Camera};

/// A real bug found by a target: what was violated, with the details to reproduce it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Violation {
    pub target: &'static str,
    pub message: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.target, self.message)
    }
}

impl std::error::Error for Violation {}

fn violation(target: &'static str, message: impl Into<String>) -> Violation {
    Violation {
        target,
        message: message.into(),
    }
}

/// Decodes `data` as a `T`, taking all of it (as `fuzz_target!` does with a typed input).
/// `None` only if `arbitrary` cannot build a `T` at all (it never refuses for these types).
fn decode<'a, T: Arbitrary<'a>>(data: &'a [u8]) -> Option<T> {
    T::arbitrary_take_rest(Unstructured::new(data)).ok()
}

// ------------------------------------------------------------------------------------------
// Rasterizer watertightness.
// ------------------------------------------------------------------------------------------

/// Sub-pixel units per pixel (the rasterizer's 8 bits of fixed point).
const ONE: i64 = 1 << fragrace_emu::raster::SUBPIXEL_BITS;

/// The input of [`raster_watertight`].
#[derive(Arbitrary, Clone, Debug)]
pub struct RasterInput {
    /// Viewport side: 8, 16 or 32 pixels (`size % 3`).
    pub size: u8,
    /// Tile side: 8, 16, 32 or 64 pixels (`tile % 4`).
    pub tile: u8,
    /// Samples per pixel: 1, 2, 4 or 8 (`samples % 4`).
    pub samples: u8,
    /// Up to 3 tilings, each drawn as its own layer.
    pub tilings: Vec<Tiling>,
    /// Up to 8 arbitrary triangles (object space; non-finite coordinates become 0, so that
    /// the draw is not refused), drawn through `matrix` (identity when `None`).
    pub others: Vec<[[f32; 3]; 3]>,
    pub matrix: Option<[f32; 16]>,
}

/// Triangles that cover a region exactly (in window sub-pixel units, exact in the
/// rasterizer's fixed point, so the region is known exactly).
#[derive(Arbitrary, Clone, Debug)]
pub enum Tiling {
    Grid(Grid),
    Fan(Fan),
}

/// A grid of rectangular cells, each split into two triangles, covering a rectangle.
#[derive(Arbitrary, Clone, Debug)]
pub struct Grid {
    /// Coordinates are multiples of 1, 16, 64, 128 or 256 sub-pixel units (`quantum % 5`):
    /// coarse quanta put edges and vertices exactly on pixel centres and sample positions.
    pub quantum: u8,
    /// Top-left corner, mapped into `[-side/2, 3 side/2)` pixels.
    pub origin: [i16; 2],
    /// Column widths and row heights (1 to 4 of each), in quanta, up to the viewport side.
    pub widths: Vec<u16>,
    pub heights: Vec<u16>,
    /// Bit `c`: cell `c` is split along its other diagonal.
    pub diagonals: u16,
    /// Bit `t`: triangle `t` is wound the other way.
    pub flips: u32,
    /// Depth: constant `depth[0] / 128` in NDC; with `clip`, the plane
    /// `z = depth[0] / 32 + depth[1] x' + depth[2] y'` (scaled so that it can cross the near
    /// and far planes inside the viewport), clipped by the rasterizer.
    pub depth: [i8; 3],
    pub clip: bool,
}

/// A fan of 5 to 8 triangles around a centre: a closed star-shaped polygon.
#[derive(Arbitrary, Clone, Debug)]
pub struct Fan {
    pub quantum: u8,
    pub centre: [i16; 2],
    /// Per spoke: angle jitter within its sector, and radius in quanta.
    pub spokes: Vec<(u8, u16)>,
    pub flips: u16,
    pub depth: i8,
}

/// What [`raster_watertight`] checked.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterReport {
    pub tilings: u32,
    /// Samples strictly inside a tiled region (each must be covered exactly once).
    pub interior_samples: u64,
    pub fragments: u64,
}

/// A tiling as the rasterizer gets it, with its region.
struct Layer {
    /// Window sub-pixel position (exact) and NDC z of each vertex.
    verts: Vec<([i64; 2], f64)>,
    tris: Vec<[u32; 3]>,
    region: Region,
}

enum Region {
    /// `[x0, x1] x [y0, y1]`; with a depth plane (z per sub-pixel unit), only where
    /// `-1 < z < 1`.
    Rect {
        lo: [i64; 2],
        hi: [i64; 2],
        plane: Option<[f64; 3]>,
    },
    /// The star polygon around `centre` with vertices `ring` (positive orientation).
    Star {
        centre: [i64; 2],
        ring: Vec<[i64; 2]>,
    },
}

const QUANTA: [i64; 5] = [1, 16, 64, 128, 256];

fn cross(o: [i64; 2], a: [i64; 2], b: [i64; 2]) -> i64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Maps `v` to a multiple of `q` in `[-span/2, 3 span/2)`.
fn place(v: i16, q: i64, span: i64) -> i64 {
    let steps = (2 * span / q).max(1);
    (v as i64).rem_euclid(steps) * q - span / 2 / q * q
}

impl Grid {
    fn layer(&self, span: i64) -> Layer {
        let q = QUANTA[self.quantum as usize % QUANTA.len()];
        let lo = [
            place(self.origin[0], q, span),
            place(self.origin[1], q, span),
        ];
        let sizes = |v: &[u16]| -> Vec<i64> {
            if v.is_empty() {
                return vec![(span / 2 / q).max(1) * q];
            }
            v.iter()
                .take(4)
                .map(|&w| q * (1 + w as i64 % (span / q).max(1)))
                .collect()
        };
        let (ws, hs) = (sizes(&self.widths), sizes(&self.heights));
        let xs: Vec<i64> = std::iter::once(lo[0])
            .chain(ws.iter().scan(lo[0], |x, w| {
                *x += w;
                Some(*x)
            }))
            .collect();
        let ys: Vec<i64> = std::iter::once(lo[1])
            .chain(hs.iter().scan(lo[1], |y, h| {
                *y += h;
                Some(*y)
            }))
            .collect();
        let plane = self.clip.then(|| {
            // z = a + b X + c Y (X, Y in sub-pixel units): a in [-4, 4), and a change of up
            // to 4 across the viewport in each direction.
            let s = 32.0 * span as f64;
            [
                self.depth[0] as f64 / 32.0,
                self.depth[1] as f64 / s,
                self.depth[2] as f64 / s,
            ]
        });
        let z = |p: [i64; 2]| match plane {
            Some([a, b, c]) => a + b * p[0] as f64 + c * p[1] as f64,
            None => self.depth[0] as f64 / 128.0,
        };
        let cols = ws.len();
        let mut verts = Vec::new();
        for &y in &ys {
            for &x in &xs {
                verts.push(([x, y], z([x, y])));
            }
        }
        let at = |c: usize, r: usize| (r * (cols + 1) + c) as u32;
        let mut tris = Vec::new();
        for r in 0..hs.len() {
            for c in 0..cols {
                let (a, b, cc, d) = (at(c, r), at(c + 1, r), at(c + 1, r + 1), at(c, r + 1));
                let cell = r * cols + c;
                if self.diagonals >> (cell % 16) & 1 == 0 {
                    tris.push([a, b, cc]);
                    tris.push([a, cc, d]);
                } else {
                    tris.push([a, b, d]);
                    tris.push([b, cc, d]);
                }
            }
        }
        flip(&mut tris, self.flips);
        Layer {
            verts,
            tris,
            region: Region::Rect {
                lo,
                hi: [*xs.last().unwrap_or(&lo[0]), *ys.last().unwrap_or(&lo[1])],
                plane,
            },
        }
    }
}

/// Winds triangle `t` the other way when bit `t` of `flips` is set.
fn flip(tris: &mut [[u32; 3]], flips: u32) {
    for (t, tri) in tris.iter_mut().enumerate() {
        if flips >> (t % 32) & 1 == 1 {
            tri.swap(1, 2);
        }
    }
}

impl Fan {
    /// The fan, or `None` when rounding to the quantum left it not strictly star-shaped
    /// (two spokes in one direction, or a gap of half a turn or more).
    fn layer(&self, span: i64) -> Option<Layer> {
        let q = QUANTA[self.quantum as usize % QUANTA.len()];
        let c = [
            place(self.centre[0], q, span),
            place(self.centre[1], q, span),
        ];
        let mut spokes = self.spokes.clone();
        spokes.truncate(8);
        while spokes.len() < 5 {
            spokes.push((128, (span / 4 / q) as u16));
        }
        let n = spokes.len();
        let ring: Vec<[i64; 2]> = spokes
            .iter()
            .enumerate()
            .map(|(i, &(jitter, radius))| {
                // Each spoke in its own sector: consecutive gaps stay below 2 * 0.95 turns / n.
                let a = std::f64::consts::TAU * (i as f64 + jitter as f64 / 256.0 * 0.9) / n as f64;
                let r = (q * (1 + radius as i64 % (span / q).max(1))) as f64;
                let snap = |v: f64| (v / q as f64).round() as i64 * q;
                [c[0] + snap(r * a.cos()), c[1] + snap(r * a.sin())]
            })
            .collect();
        let mut turn = 0.0;
        for i in 0..n {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            if cross(c, a, b) <= 0 {
                return None;
            }
            let ang = |p: [i64; 2]| ((p[1] - c[1]) as f64).atan2((p[0] - c[0]) as f64);
            turn += (ang(b) - ang(a)).rem_euclid(std::f64::consts::TAU);
        }
        if (turn - std::f64::consts::TAU).abs() > 1e-6 {
            return None;
        }
        let z = self.depth as f64 / 128.0;
        let mut verts = vec![(c, z)];
        verts.extend(ring.iter().map(|&p| (p, z)));
        let mut tris: Vec<[u32; 3]> = (0..n)
            .map(|i| [0, 1 + i as u32, 1 + ((i + 1) % n) as u32])
            .collect();
        flip(&mut tris, self.flips as u32);
        Some(Layer {
            verts,
            tris,
            region: Region::Star { centre: c, ring },
        })
    }
}

impl Layer {
    /// Whether sample `p` is strictly inside the tiled region, away from every clip plane
    /// (then exactly one triangle must cover it).
    fn interior(&self, p: [i64; 2]) -> bool {
        match &self.region {
            Region::Rect { lo, hi, plane } => {
                let inside = lo[0] < p[0] && p[0] < hi[0] && lo[1] < p[1] && p[1] < hi[1];
                inside
                    && plane.is_none_or(|[a, b, c]| {
                        // The clipped vertices are snapped (half a sub-pixel unit) and the
                        // vertices' z are f32: stay 1/16 pixel and 1e-4 in z from the planes.
                        let z = a + b * p[0] as f64 + c * p[1] as f64;
                        let slope = (b * b + c * c).sqrt() * ONE as f64;
                        let far_enough = |d: f64| d > 1e-4 && d > slope / 16.0;
                        far_enough(z + 1.0) && far_enough(1.0 - z)
                    })
            }
            Region::Star { centre, ring } => {
                let n = ring.len();
                (0..n).any(|i| {
                    let (a, b) = (ring[i], ring[(i + 1) % n]);
                    cross(*centre, a, p) >= 0 && cross(a, b, p) > 0 && cross(b, *centre, p) >= 0
                })
            }
        }
    }

    /// Whether sample `p` is strictly outside every triangle (then none may cover it).
    fn exterior(&self, p: [i64; 2]) -> bool {
        self.tris.iter().all(|t| {
            let [a, b, c] = t.map(|i| self.verts[i as usize].0);
            let e = [cross(a, b, p), cross(b, c, p), cross(c, a, p)];
            let area = cross(a, b, c);
            // Degenerate triangles cover nothing; otherwise outside = some edge strictly
            // on the outer side for the triangle's orientation.
            area == 0 || e.iter().any(|&v| v * area.signum() < 0)
        })
    }

    /// The mesh in NDC (`x = X / (side / 2) - 1`, `y = 1 - Y / (side / 2)`: exact for
    /// power-of-two sides), drawn with the identity matrix.
    fn mesh(&self, side: u32) -> Mesh {
        let half = (side as i64 * ONE / 2) as f64;
        Mesh {
            positions: self
                .verts
                .iter()
                .map(|&([x, y], z)| {
                    Vec3::new(
                        (x as f64 / half - 1.0) as f32,
                        (1.0 - y as f64 / half) as f32,
                        z as f32,
                    )
                })
                .collect(),
            normals: None,
            indices: self.tris.clone(),
        }
    }
}

/// Counts covered samples: `counts[layer][pixel][sample]`, where the layer is `base`, plus
/// the primitive id with `per_primitive`.
struct CoverageCount {
    counts: Buf<u32>,
    samples: u32,
    pixels: u32,
    base: u32,
    per_primitive: bool,
}

impl FragmentKernel for CoverageCount {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("fuzz-coverage-count")
    }
    async fn shade(&self, f: impl Fragment) {
        let layer = if self.per_primitive {
            self.base + f.primitive_id()
        } else {
            self.base
        };
        let at = (layer * self.pixels + f.pixel_index()) * self.samples;
        let cov = f.coverage();
        for s in 0..self.samples {
            if cov >> s & 1 == 1 {
                f.atomic_add(self.counts, at + s, 1).await;
            }
        }
    }
}

/// The raster target on raw bytes.
pub fn raster_watertight(data: &[u8]) -> Result<RasterReport, Violation> {
    match decode::<RasterInput>(data) {
        Some(input) => raster_watertight_input(&input),
        None => Ok(RasterReport::default()),
    }
}

/// The raster target on a decoded input.
pub fn raster_watertight_input(input: &RasterInput) -> Result<RasterReport, Violation> {
    const T: &str = "raster_watertight";
    let side = [8u32, 16, 32][input.size as usize % 3];
    let tile = [8u32, 16, 32, 64][input.tile as usize % 4];
    let samples = [
        SampleCount::X1,
        SampleCount::X2,
        SampleCount::X4,
        SampleCount::X8,
    ][input.samples as usize % 4];
    let ns = samples.count() as u32;
    let span = side as i64 * ONE;
    let layers: Vec<Layer> = input
        .tilings
        .iter()
        .take(3)
        .filter_map(|t| match t {
            Tiling::Grid(g) => Some(g.layer(span)),
            Tiling::Fan(f) => f.layer(span),
        })
        .collect();
    let others = Mesh {
        positions: input
            .others
            .iter()
            .take(8)
            .flatten()
            .map(|p| {
                let v = Vec3::from_array(*p);
                if v.is_finite() {
                    v
                } else {
                    Vec3::ZERO
                }
            })
            .collect(),
        normals: None,
        indices: (0..input.others.len().min(8) as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect(),
    };
    let pixels = side * side;
    let per_layer = pixels * ns;
    let mut device = Device::new();
    let slots = per_layer as u64 * (layers.len() + others.indices.len()) as u64;
    let counts = device
        .buffer::<u32>("coverage", slots.max(1))
        .map_err(|e| violation(T, format!("counting buffer: {e}")))?;
    let mut fb = Framebuffer::new(side, side, samples, tile, &[])
        .map_err(|e| violation(T, format!("framebuffer: {e}")))?;
    let state = PassState {
        raster: RasterState {
            samples,
            ..RasterState::default()
        },
        ..PassState::default()
    };
    let exec = ExecConfig {
        threads: 1,
        ..ExecConfig::ordered()
    };
    let mut report = RasterReport::default();
    for (i, layer) in layers.iter().enumerate() {
        let mesh = layer.mesh(side);
        let kernel = CoverageCount {
            counts,
            samples: ns,
            pixels,
            base: i as u32,
            per_primitive: false,
        };
        let r = device
            .draw(
                &mut fb,
                &Draw::new(&mesh, Mat4::IDENTITY),
                &state,
                &kernel,
                &exec,
            )
            .map_err(|e| violation(T, format!("tiling {i} refused: {e}")))?;
        report.fragments += r.stats.fragments_generated;
    }
    if !others.indices.is_empty() {
        let m = input
            .matrix
            .map(|m| Mat4::from_cols_array(&m))
            .unwrap_or(Mat4::IDENTITY);
        let kernel = CoverageCount {
            counts,
            samples: ns,
            pixels,
            base: layers.len() as u32,
            per_primitive: true,
        };
        let r = device
            .draw(&mut fb, &Draw::new(&others, m), &state, &kernel, &exec)
            .map_err(|e| violation(T, format!("arbitrary triangles refused: {e}")))?;
        report.fragments += r.stats.fragments_generated;
    }
    let counts = device
        .memory
        .read(counts)
        .map_err(|e| violation(T, e.to_string()))?;
    let offsets: Vec<[i64; 2]> = samples
        .positions()
        .iter()
        .map(|&(x, y)| [(x * ONE as f32) as i64, (y * ONE as f32) as i64])
        .collect();
    for (l, layer) in layers.iter().enumerate() {
        report.tilings += 1;
        for py in 0..side {
            for px in 0..side {
                for (s, o) in offsets.iter().enumerate() {
                    let p = [px as i64 * ONE + o[0], py as i64 * ONE + o[1]];
                    let c = counts[((l as u32 * pixels + py * side + px) * ns) as usize + s];
                    let what = || {
                        format!(
                            "tiling {l} ({} triangles, {side}x{side}, {ns} samples, tile {tile}): \
                             pixel ({px}, {py}) sample {s} at sub-pixel ({}, {})",
                            layer.tris.len(),
                            p[0],
                            p[1]
                        )
                    };
                    if c > 1 {
                        return Err(violation(T, format!("{}: covered {c} times", what())));
                    }
                    if layer.interior(p) {
                        report.interior_samples += 1;
                        if c == 0 {
                            return Err(violation(
                                T,
                                format!("{}: a crack (inside, not covered)", what()),
                            ));
                        }
                    } else if c > 0 && layer.exterior(p) {
                        return Err(violation(
                            T,
                            format!("{}: covered but outside every triangle", what()),
                        ));
                    }
                }
            }
        }
    }
    let first = layers.len() * per_layer as usize;
    if let Some((i, &c)) = counts[first..].iter().enumerate().find(|&(_, &c)| c > 1) {
        let t = i / per_layer as usize;
        let p = i % per_layer as usize / ns as usize;
        return Err(violation(
            T,
            format!(
                "arbitrary triangle {t} {:?} through {:?}: pixel ({}, {}) sample {} covered {c} times",
                input.others.get(t),
                input.matrix,
                p as u32 % side,
                p as u32 / side,
                i % ns as usize
            ),
        ));
    }
    Ok(report)
}

// ------------------------------------------------------------------------------------------
// Every kernel against its oracle under arbitrary schedules.
// ------------------------------------------------------------------------------------------

/// The input of [`kernel_oracle`].
#[derive(Arbitrary, Clone, Debug)]
pub struct KernelInput {
    /// The algorithm: `algo % (n + 1)`-th of the registry's `n`; `n` selects the linked list
    /// with its planted bug ([`KernelInput::planted`] builds such an input).
    pub algo: u8,
    /// Viewport: 4 to 24 pixels each way.
    pub width: u8,
    pub height: u8,
    /// k of the k-buffers: 1 to 8.
    pub k: u8,
    /// Invocations in flight: 2 to 8.
    pub window: u8,
    /// Azimuth and elevation.
    pub camera: [i8; 2],
    /// Up to 9 vertices (coordinates / 16) and 6 triangles (indices modulo the vertices).
    pub vertices: Vec<[i8; 3]>,
    pub triangles: Vec<[u8; 3]>,
    /// The schedule: at step s, run the `schedule[s] % n`-th runnable invocation.
    pub schedule: Vec<u8>,
}

/// The algorithms the oracle target picks from (registry order).
pub fn oracle_algorithms() -> &'static [&'static str] {
    static NAMES: OnceLock<Vec<&'static str>> = OnceLock::new();
    NAMES.get_or_init(fragrace_kernels::names)
}

impl KernelInput {
    /// The selector value of the planted-bug mode.
    pub fn planted_selector() -> u8 {
        oracle_algorithms().len() as u8
    }
    /// Whether this input runs the planted bug.
    pub fn planted(&self) -> bool {
        self.algo as usize % (oracle_algorithms().len() + 1) == oracle_algorithms().len()
    }

    fn spec(&self, algo: &str) -> Option<RunSpec> {
        let nv = self.vertices.len().min(9);
        if nv < 3 || self.triangles.is_empty() {
            return None;
        }
        let positions = self.vertices[..nv]
            .iter()
            .map(|v| v.map(|c| c as f32 / 16.0))
            .collect();
        let indices = self
            .triangles
            .iter()
            .take(6)
            .map(|t| t.map(|i| (i as usize % nv) as u32))
            .collect();
        Some(RunSpec {
            scene: SceneSpec::Inline {
                positions,
                indices,
                radius: None,
            },
            camera: Camera::new(
                self.camera[0] as f32 * 1.5,
                self.camera[1] as f32 / 128.0 * 80.0,
            ),
            width: 4 + self.width as u32 % 21,
            height: 4 + self.height as u32 % 21,
            algo: algo.to_string(),
            params: Params {
                k: 1 + self.k as u32 % 8,
                ..Params::default()
            },
            exec: ExecConfig {
                mode: ExecMode::Scheduled(ScheduleConfig {
                    policy: Policy::Bytes(self.schedule.clone()),
                    seed: 0,
                    window: 2 + self.window as usize % 7,
                    record: false,
                }),
                threads: 1,
                max_steps: 1 << 16,
                ..ExecConfig::default()
            },
        })
    }
}

/// What [`kernel_oracle`] did.
#[derive(Clone, Debug, PartialEq)]
pub enum KernelOutcome {
    /// The input makes no scene (fewer than 3 vertices, no triangle, a degenerate mesh).
    Skipped,
    /// A registry algorithm ran and kept its hazard-class contract.
    Checked {
        algo: &'static str,
        class: HazardClass,
        epr: f64,
        /// Hazards, faults, failed checks or error pixels (allowed only to hazard-prone
        /// algorithms, and error pixels to approximate ones).
        anomalous: bool,
    },
    /// The linked list with its planted bug ran; `found`: the schedule exposed it (the
    /// detector saw a torn record, or the in-pass reader a half-written node).
    Planted { found: bool, torn: u64 },
}

/// The oracle target on raw bytes.
pub fn kernel_oracle(data: &[u8]) -> Result<KernelOutcome, Violation> {
    match decode::<KernelInput>(data) {
        Some(input) => kernel_oracle_input(&input),
        None => Ok(KernelOutcome::Skipped),
    }
}

/// The oracle target on a decoded input. The contract checked, by declared hazard class:
/// a hazard-free or needs-interlock algorithm has no failed invariant, no fault, no hazard,
/// and, unless it dropped fragments (capacity overflow: which ones is order-dependent), the
/// same error pixels against the truth under this schedule as under the `ordered`
/// executor (0 for the exact ones; approximations such as `wboit` may differ from the
/// truth, but identically). A hazard-prone algorithm may show anything but a panic.
pub fn kernel_oracle_input(input: &KernelInput) -> Result<KernelOutcome, Violation> {
    const T: &str = "kernel_oracle";
    let names = oracle_algorithms();
    let planted = input.planted();
    let name = if planted {
        "ll"
    } else {
        names[input.algo as usize % (names.len() + 1)]
    };
    let Some(spec) = input.spec(name) else {
        return Ok(KernelOutcome::Skipped);
    };
    let Ok(loaded) = run::load(&spec) else {
        return Ok(KernelOutcome::Skipped);
    };
    if planted {
        let bug = LinkedList::planted_bug();
        let r = bug
            .run(&loaded.frame(&spec), &spec.params, &spec.exec)
            .map_err(|e| violation(T, format!("ll planted bug: run failed: {e}")))?;
        let half = r
            .checks
            .iter()
            .any(|c| c.name.contains("half-written") && !c.passed);
        if let Some(c) = r
            .checks
            .iter()
            .find(|c| !c.passed && !c.name.contains("half-written"))
        {
            // The bug is latent after the pass: everything else must hold.
            return Err(violation(
                T,
                format!("ll planted bug broke `{}`: {} ({spec:?})", c.name, c.detail),
            ));
        }
        let torn = r.report.hazards.torn;
        return Ok(KernelOutcome::Planted {
            found: torn > 0 || half,
            torn,
        });
    }
    let truth = run::truth(&spec, &loaded)
        .map_err(|e| violation(T, format!("truth failed on a loadable scene: {e}")))?;
    let ordered_spec = RunSpec {
        exec: ExecConfig {
            threads: 1,
            ..ExecConfig::ordered()
        },
        ..spec.clone()
    };
    let Ok(reference) = run::check_with(&ordered_spec, &loaded, &truth) else {
        // The algorithm refuses these parameters (under every executor).
        return Ok(KernelOutcome::Skipped);
    };
    let checked = run::check_with(&spec, &loaded, &truth).map_err(|e| {
        violation(
            T,
            format!("{name} ran under `ordered` but failed under the schedule: {e} ({spec:?})"),
        )
    })?;
    let info = &checked.rendered.info;
    let result = &checked.rendered.result;
    if info.hazard != HazardClass::HazardProne {
        let class = info.hazard.name();
        let fail = |what: String| violation(T, format!("{name} ({class}): {what}; spec {spec:?}"));
        if let Some(c) = checked.failed_checks().first() {
            return Err(fail(format!("invariant `{}` failed: {}", c.name, c.detail)));
        }
        if result.report.stats.faulted > 0 {
            return Err(fail(format!("faulted: {:?}", result.report.faults.first())));
        }
        if checked.hazards().total() > 0 {
            return Err(fail(format!(
                "hazards {:?}, first {:?}",
                checked.hazards(),
                result.report.hazard_list.first()
            )));
        }
        let dropped = result.dropped > 0 || reference.rendered.result.dropped > 0;
        if !dropped && checked.metrics.error_pixels != reference.metrics.error_pixels {
            return Err(fail(format!(
                "{} error pixels (EPR {}) under the schedule, {} (EPR {}) under `ordered`; first {:?}",
                checked.metrics.error_pixels,
                checked.metrics.epr,
                reference.metrics.error_pixels,
                reference.metrics.epr,
                checked.metrics.first_error
            )));
        }
    }
    Ok(KernelOutcome::Checked {
        algo: info.name,
        class: info.hazard,
        epr: checked.metrics.epr,
        anomalous: checked.anomalous(),
    })
}

// ------------------------------------------------------------------------------------------
// OBJ loader.
// ------------------------------------------------------------------------------------------

/// What [`obj_loader`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjOutcome {
    Rejected,
    /// Accepted: a valid mesh of this many triangles, which round-trips.
    Parsed {
        triangles: usize,
    },
}

/// The mesh as OBJ text (`v` lines with shortest round-trip floats, 1-based `f` lines).
pub fn write_obj(mesh: &Mesh) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
    }
    for t in &mesh.indices {
        let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

/// The OBJ target: never panics; an accepted mesh is valid, has triangles, and parses back
/// identical from [`write_obj`]'s text.
pub fn obj_loader(data: &[u8]) -> Result<ObjOutcome, Violation> {
    const T: &str = "obj_loader";
    let Ok(mesh) = parse_obj_bytes(data) else {
        return Ok(ObjOutcome::Rejected);
    };
    if let Err(e) = mesh.validate() {
        return Err(violation(T, format!("accepted an invalid mesh: {e}")));
    }
    if mesh.indices.is_empty() {
        return Err(violation(T, "accepted a mesh with no triangle"));
    }
    let text = write_obj(&mesh);
    match parse_obj_bytes(text.as_bytes()) {
        Ok(back) if back == mesh => {}
        Ok(back) => {
            return Err(violation(
                T,
                format!("round trip changed the mesh: {mesh:?} became {back:?}"),
            ))
        }
        Err(e) => {
            return Err(violation(
                T,
                format!("round trip refused: {e}; text:\n{text}"),
            ))
        }
    }
    Ok(ObjOutcome::Parsed {
        triangles: mesh.indices.len(),
    })
}

// ------------------------------------------------------------------------------------------
// Case-file parser.
// ------------------------------------------------------------------------------------------

/// What [`case_parser`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CaseOutcome {
    /// The bytes parsed as a case (and round-tripped).
    pub parsed: bool,
    /// A case built from the bytes round-tripped.
    pub built: bool,
}

/// Serialises a case as [`case::write`] does and parses it back; it must come back equal.
pub fn case_round_trip(c: &Case) -> Result<(), Violation> {
    const T: &str = "case_parser";
    let json = serde_json::to_vec_pretty(c).map_err(|e| violation(T, format!("serialise: {e}")))?;
    match case::parse(&json, "<round-trip>") {
        Ok(back) if &back == c => Ok(()),
        Ok(back) => Err(violation(
            T,
            format!("round trip changed the case: {c:?} became {back:?}"),
        )),
        Err(e) => Err(violation(
            T,
            format!(
                "a parsed case does not parse back after serialising: {e}; file:\n{}",
                String::from_utf8_lossy(&json)
            ),
        )),
    }
}

/// The case-file target: [`case::parse`] never panics, a case it accepts round-trips, and a
/// case built from the same bytes ([`arbitrary_case`]) round-trips.
pub fn case_parser(data: &[u8]) -> Result<CaseOutcome, Violation> {
    let mut out = CaseOutcome {
        parsed: false,
        built: false,
    };
    if let Ok(c) = case::parse(data, "<fuzz>") {
        case_round_trip(&c)?;
        out.parsed = true;
    }
    if let Ok(c) = arbitrary_case(&mut Unstructured::new(data)) {
        case_round_trip(&c)?;
        out.built = true;
    }
    Ok(out)
}

/// A finite f32 from the bytes (JSON has no NaN or infinity; a case never holds one).
fn finite_f32(u: &mut Unstructured<'_>) -> arbitrary::Result<f32> {
    let v = f32::arbitrary(u)?;
    Ok(if v.is_finite() { v } else { 0.0 })
}

fn finite_f64(u: &mut Unstructured<'_>) -> arbitrary::Result<f64> {
    let v = f64::arbitrary(u)?;
    Ok(if v.is_finite() { v } else { 0.0 })
}

/// A case with every field drawn from `u` (finite floats; any strings, numbers, policies).
#[allow(clippy::needless_update)] // `..default()` is for fields added to ExecConfig later
pub fn arbitrary_case(u: &mut Unstructured<'_>) -> arbitrary::Result<Case> {
    let scene = match u.int_in_range(0..=2)? {
        0 => SceneSpec::Builtin(String::arbitrary(u)?),
        1 => SceneSpec::Obj {
            path: String::arbitrary(u)?.into(),
            sha256: Option::<String>::arbitrary(u)?,
        },
        _ => {
            let n = u.int_in_range(0..=6)?;
            let mut positions = Vec::with_capacity(n);
            for _ in 0..n {
                positions.push([finite_f32(u)?, finite_f32(u)?, finite_f32(u)?]);
            }
            let m = u.int_in_range(0..=4)?;
            let mut indices = Vec::with_capacity(m);
            for _ in 0..m {
                indices.push(<[u32; 3]>::arbitrary(u)?);
            }
            let radius = if bool::arbitrary(u)? {
                Some(finite_f32(u)?)
            } else {
                None
            };
            SceneSpec::Inline {
                positions,
                indices,
                radius,
            }
        }
    };
    let policy = match u.int_in_range(0..=6)? {
        0 => Policy::Random,
        1 => Policy::Pct {
            depth: u32::arbitrary(u)?,
        },
        2 => Policy::Warp {
            lanes: u32::arbitrary(u)?,
        },
        3 => Policy::Reverse,
        4 => Policy::Fifo,
        5 => Policy::FarFirst,
        _ => Policy::Bytes(Vec::<u8>::arbitrary(u)?),
    };
    let mode = match u.int_in_range(0..=2)? {
        0 => ExecMode::Ordered,
        1 => ExecMode::Parallel,
        _ => ExecMode::Scheduled(ScheduleConfig {
            policy,
            seed: u64::arbitrary(u)?,
            window: usize::arbitrary(u)?,
            record: bool::arbitrary(u)?,
        }),
    };
    let spec = RunSpec {
        scene,
        camera: Camera {
            azimuth: finite_f32(u)?,
            elevation: finite_f32(u)?,
            fovy: finite_f32(u)?,
            fill: finite_f32(u)?,
        },
        width: u32::arbitrary(u)?,
        height: u32::arbitrary(u)?,
        algo: String::arbitrary(u)?,
        params: Params {
            k: u32::arbitrary(u)?,
            alpha: finite_f32(u)?,
            pool_per_pixel: if bool::arbitrary(u)? {
                Some(finite_f32(u)?)
            } else {
                None
            },
            spin_cap: u32::arbitrary(u)?,
            buckets: u32::arbitrary(u)?,
            fab_capacity: u32::arbitrary(u)?,
            background: [finite_f32(u)?, finite_f32(u)?, finite_f32(u)?],
            occupancy: if bool::arbitrary(u)? {
                Some(fragrace_kernels::occupancy::Occupancy {
                    d: u32::arbitrary(u)?,
                    range: [
                        fragrace_kernels::occupancy::RangeSource::Exact,
                        fragrace_kernels::occupancy::RangeSource::Bbox,
                        fragrace_kernels::occupancy::RangeSource::Hull,
                    ][u.int_in_range(0..=2)?],
                    fill: if bool::arbitrary(u)? {
                        fragrace_kernels::occupancy::FillMode::Plain
                    } else {
                        fragrace_kernels::occupancy::FillMode::Atomic
                    },
                })
            } else {
                None
            },
            merge: fragrace_kernels::merging::MergeParams {
                thickness: if bool::arbitrary(u)? {
                    fragrace_kernels::merging::Thickness::Fixed(finite_f32(u)?)
                } else {
                    fragrace_kernels::merging::Thickness::ZResolution {
                        multiple: finite_f32(u)?,
                        bits: u32::arbitrary(u)?,
                    }
                },
                beta: finite_f32(u)?,
            },
            range: [
                fragrace_kernels::occupancy::RangeSource::Exact,
                fragrace_kernels::occupancy::RangeSource::Bbox,
                fragrace_kernels::occupancy::RangeSource::Hull,
            ][u.int_in_range(0..=2)?],
            // Not drawn from the input (so that existing corpora decode as before).
            geometry_culling: Default::default(),
        },
        exec: ExecConfig {
            mode,
            threads: usize::arbitrary(u)?,
            batch: usize::arbitrary(u)?,
            lockstep: bool::arbitrary(u)?,
            max_steps: u64::arbitrary(u)?,
            max_waits: u64::arbitrary(u)?,
            contention: bool::arbitrary(u)?,
            block: u32::arbitrary(u)?,
            // Fields added later keep their defaults (and still round-trip).
            ..ExecConfig::default()
        },
    };
    let observed = Observation {
        epr: finite_f64(u)?,
        error_pixels: u64::arbitrary(u)?,
        lost_updates: u64::arbitrary(u)?,
        races: u64::arbitrary(u)?,
        torn: u64::arbitrary(u)?,
        faults: u64::arbitrary(u)?,
        dropped: u64::arbitrary(u)?,
        failed_checks: Vec::<String>::arbitrary(u)?,
        first_error: Option::<(u32, u32)>::arbitrary(u)?,
        first_hazard: Option::<String>::arbitrary(u)?,
        digest: String::arbitrary(u)?,
    };
    let size = |u: &mut Unstructured<'_>| -> arbitrary::Result<Option<Size>> {
        Ok(if bool::arbitrary(u)? {
            Some(Size {
                triangles: usize::arbitrary(u)?,
                pixels: u64::arbitrary(u)?,
                window: usize::arbitrary(u)?,
                schedule_steps: usize::arbitrary(u)?,
            })
        } else {
            None
        })
    };
    Ok(Case {
        version: case::VERSION,
        verdict: String::arbitrary(u)?,
        spec,
        observed,
        original_size: size(u)?,
        shrunk_size: size(u)?,
    })
}
