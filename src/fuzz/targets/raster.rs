//! The rasterizer's watertightness on arbitrary tilings (the `raster_watertight` target).

use arbitrary::Arbitrary;
use fragrace_emu::{
    Buf, Device, Draw, ExecConfig, Fragment, FragmentKernel, Framebuffer, KernelInfo, Mesh,
    PassState, RasterState, SampleCount,
};
use glam::{Mat4, Vec3};

use super::{decode, violation, Violation};

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
