//! The run-time selection (section 5), as four algorithms:
//!
//! - `presorted`: the fragment-shader option. The CPU picks the segment of the viewpoint's
//!   partition (section 4.2); each fragment of an instance passes the facing test (the
//!   back-face culling of section 3.1, as the same dot product: front and back copies then
//!   partition viewpoint space exactly) and its test planes, `dot(p, [v, -1]) > 0`, or is
//!   discarded. Survivors are blended back to front by fixed-function "over", which the
//!   emulator applies in API order whatever order the fragments were shaded in. Every copy
//!   tests its planes, the last one included, and the depth test is off: the paper leaves
//!   the last copy's planes to a LESS depth test (section 4.1: drawn iff no earlier copy
//!   was), but LESS also rejects any fragment whose rasterized depth is not strictly below
//!   that of a fragment drawn before it, and rasterized depths are those of the triangle
//!   with its vertices snapped to 1/256 pixel: up to about 2e-4 off in window depth at
//!   40 x 40, where a fold of two grazing triangles at a silhouette, or two triangles that
//!   meet along a line, put fragments in the exact back-to-front order whose rasterized
//!   depths are equal or inverted (the bunny's lists lost one such fragment at azimuth
//!   27.920723, elevation -38.48013). The planes alone select exactly one copy (each
//!   instance keeps its exact region's planes), so nothing is dropped.
//! - `presorted-vs`: the vertex-shader option: the same test per vertex, failing vertices
//!   moved to the viewpoint so that the near plane culls the triangle (vertices are no
//!   longer shared, as the paper notes). Run on the host as the draw's vertex stage.
//! - `presorted-ssbo`: a renderer without fixed-function blending: the fragment kernel
//!   reads, blends and writes the pixel in a buffer with plain accesses. Fragments of one
//!   pixel race: hazard-prone.
//! - `presorted-ssbo-interlock`: the same inside ordered pixel interlock (critical sections
//!   in primitive order): exact. Without a depth test, the SSBO variants test every copy's
//!   planes (each copy's exact region).
//!
//! Where the lists come from: [`Params::presorted`] names a file written by `fragrace
//! presort`; without it the mesh is preprocessed on first use with 6 partitions (cached
//! for the process, by mesh hash).

use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use fragrace_emu::{
    Buf, CompareFunc, DepthState, ExecConfig, Format, Fragment, FragmentKernel, InterlockMode,
    KernelInfo, Mesh, PassReport, SampleCount, TargetState,
};
use glam::{DMat4, DVec3, DVec4, Vec3};

use super::{file, graph, input, PresortConfig, Presorted, Silent, WorldClip};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};
use crate::common::{self, capture_state, framebuffer, pixels};

/// One segment made ready to draw: its index buffer and per-instance constants (the plane
/// "texture" of the fragment-shader option, read-only).
#[derive(Debug)]
pub struct SegmentData {
    pub mesh: Mesh,
    /// Each instance's input triangle (its colour and facing).
    pub tri: Vec<u32>,
    /// Each instance's piece (the input triangle unless triangles were split).
    pub piece: Vec<u32>,
    pub facing: Vec<[f32; 4]>,
    /// Instance i's planes are `planes[offsets[i]..offsets[i + 1]]`.
    pub offsets: Vec<u32>,
    pub planes: Vec<[f32; 4]>,
    /// Instance i's piece clips are `clips[clip_offsets[i]..clip_offsets[i + 1]]` (none
    /// for a whole triangle).
    pub clip_offsets: Vec<u32>,
    pub clips: Vec<WorldClip>,
}

/// Preprocessed lists of one mesh, ready to draw.
#[derive(Debug)]
pub struct Prepared {
    pub lists: Presorted,
    pub segments: Vec<SegmentData>,
}

/// The facing test plane of a triangle (world space, `dot(p, [v, -1]) > 0` in front).
pub fn facing_plane(mesh: &Mesh, tri: u32, back: bool) -> [f32; 4] {
    let t = mesh.indices[tri as usize].map(|i| mesh.positions[i as usize].as_dvec3());
    let p = graph::facing(&t, back);
    [p.n.x as f32, p.n.y as f32, p.n.z as f32, (-p.d) as f32]
}

impl Prepared {
    pub fn new(mesh: &Mesh, lists: Presorted) -> Prepared {
        let positions = mesh.positions.clone();
        let segments = lists
            .segments
            .iter()
            .map(|s| {
                let mut offsets = vec![0u32];
                let mut planes = Vec::new();
                let mut clip_offsets = vec![0u32];
                let mut clips = Vec::new();
                for i in &s.instances {
                    planes.extend_from_slice(&i.planes);
                    offsets.push(planes.len() as u32);
                    clips.extend_from_slice(&lists.pieces[i.piece as usize].clips);
                    clip_offsets.push(clips.len() as u32);
                }
                let tri: Vec<u32> = s
                    .instances
                    .iter()
                    .map(|i| lists.pieces[i.piece as usize].tri)
                    .collect();
                SegmentData {
                    mesh: Mesh {
                        positions: positions.clone(),
                        normals: None,
                        indices: s
                            .instances
                            .iter()
                            .map(|i| mesh.indices[lists.pieces[i.piece as usize].tri as usize])
                            .collect(),
                    },
                    facing: s
                        .instances
                        .iter()
                        .zip(&tri)
                        .map(|(i, &t)| facing_plane(mesh, t, i.back))
                        .collect(),
                    tri,
                    piece: s.instances.iter().map(|i| i.piece).collect(),
                    offsets,
                    planes,
                    clip_offsets,
                    clips,
                }
            })
            .collect();
        Prepared { lists, segments }
    }
}

impl SegmentData {
    /// Whether instance `i` passes its tests from `eye`: its facing and its test planes.
    pub fn passes(&self, i: usize, eye: Vec3) -> bool {
        test(self.facing[i], eye)
            && self.planes[self.offsets[i] as usize..self.offsets[i + 1] as usize]
                .iter()
                .all(|p| test(*p, eye))
    }
}

impl SegmentData {
    /// Whether the fragment with barycentrics `b` on instance `i`'s input triangle is in
    /// its piece (always, for a whole triangle). The position is computed from the input
    /// triangle's corners the same way for every piece of it, and the two pieces of a cut
    /// test one plane with complementary comparisons: each fragment is in exactly one.
    pub fn in_piece(&self, i: usize, b: [f32; 3]) -> bool {
        let (lo, hi) = (
            self.clip_offsets[i] as usize,
            self.clip_offsets[i + 1] as usize,
        );
        if lo == hi {
            return true;
        }
        let t = self.mesh.indices[i];
        let p = self.mesh.positions[t[0] as usize] * b[0]
            + self.mesh.positions[t[1] as usize] * b[1]
            + self.mesh.positions[t[2] as usize] * b[2];
        self.clips[lo..hi].iter().all(|c| {
            let q = c.plane;
            (q[0] * p.x + q[1] * p.y + q[2] * p.z - q[3] >= 0.0) == c.nonneg
        })
    }

    /// Whether some instance is a piece (then the kernels test clips and may discard).
    pub fn has_clips(&self) -> bool {
        !self.clips.is_empty()
    }
}

/// The half-space test of eq. 6.
#[inline]
pub fn test(p: [f32; 4], v: Vec3) -> bool {
    p[0] * v.x + p[1] * v.y + p[2] * v.z - p[3] > 0.0
}

type Cache = Mutex<Vec<((u64, Option<PathBuf>), Arc<Prepared>)>>;

fn cache() -> &'static Cache {
    static C: OnceLock<Cache> = OnceLock::new();
    C.get_or_init(|| Mutex::new(Vec::new()))
}

/// The lists of `mesh`: from `params.presorted` or preprocessed now (6 partitions).
pub fn prepared(mesh: &Mesh, params: &Params, threads: usize) -> Result<Arc<Prepared>, AlgoError> {
    let key = (input::mesh_hash(mesh), params.presorted.clone());
    if let Some((_, p)) = cache()
        .lock()
        .map_err(|_| AlgoError::Invalid("presorted cache poisoned".into()))?
        .iter()
        .find(|(k, _)| *k == key)
    {
        return Ok(p.clone());
    }
    let lists = match &params.presorted {
        Some(path) => file::load(path, mesh).map_err(|e| AlgoError::Invalid(e.to_string()))?,
        None => super::presort(
            mesh,
            &PresortConfig {
                partitions: 6,
                threads: threads.max(1),
                ..Default::default()
            },
            &Silent,
        )
        .map_err(|e| AlgoError::Invalid(format!("presorting the mesh: {e}")))?,
    };
    let p = Arc::new(Prepared::new(mesh, lists));
    let mut c = cache()
        .lock()
        .map_err(|_| AlgoError::Invalid("presorted cache poisoned".into()))?;
    if c.len() >= 8 {
        c.remove(0);
    }
    c.push((key, p.clone()));
    Ok(p)
}

/// The viewpoint of a view-projection matrix: the point it maps to `w = 0` on the axis,
/// `VP^-1 (0, 0, 1, 0)` dehomogenized.
pub fn eye_of(view_proj: glam::Mat4) -> Result<DVec3, AlgoError> {
    let m = DMat4::from_cols_array(&view_proj.to_cols_array().map(f64::from));
    let h: DVec4 = m.inverse() * DVec4::new(0.0, 0.0, 1.0, 0.0);
    if !h.is_finite() || h.w.abs() <= 1e-300 {
        return Err(AlgoError::Invalid(
            "presorted lists need a perspective camera (the view-projection has no viewpoint)"
                .into(),
        ));
    }
    Ok(h.truncate() / h.w)
}

/// The fragment-shader selection with output to a blended target.
struct SelectKernel<'a> {
    seg: &'a SegmentData,
    eye: Vec3,
    alpha: f32,
}

impl FragmentKernel for SelectKernel<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("presorted-select").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let i = f.primitive_id() as usize;
        if !self.seg.passes(i, self.eye) || !self.seg.in_piece(i, f.barycentrics()) {
            f.discard();
            return;
        }
        let c = common::unpack_color(common::prim_color_packed(self.seg.tri[i]));
        f.output(0, [c[0], c[1], c[2], self.alpha]);
    }
}

/// The vertex-stage variant's fragment kernel: selection already done per vertex.
struct ColorKernel<'a> {
    seg: &'a SegmentData,
    alpha: f32,
}

impl FragmentKernel for ColorKernel<'_> {
    fn info(&self) -> KernelInfo {
        let k = KernelInfo::new("presorted-vs-color");
        if self.seg.has_clips() {
            k.with_discard()
        } else {
            k
        }
    }
    async fn shade(&self, f: impl Fragment) {
        let i = f.primitive_id() as usize;
        // A piece of a split triangle keeps its part of the input triangle.
        if !self.seg.in_piece(i, f.barycentrics()) {
            f.discard();
            return;
        }
        let c = common::unpack_color(common::prim_color_packed(self.seg.tri[i]));
        f.output(0, [c[0], c[1], c[2], self.alpha]);
    }
}

/// Blending by the kernel: a plain read-blend-write of the pixel's RGBA in a buffer.
struct SsboKernel<'a> {
    seg: &'a SegmentData,
    eye: Vec3,
    alpha: f32,
    color: Buf<f32>,
    interlock: Option<InterlockMode>,
}

impl FragmentKernel for SsboKernel<'_> {
    fn info(&self) -> KernelInfo {
        let k = KernelInfo::new(if self.interlock.is_some() {
            "presorted-ssbo-interlock"
        } else {
            "presorted-ssbo"
        })
        .with_discard()
        .with_pixel_array(self.color, 4);
        match self.interlock {
            Some(m) => k.with_interlock(m),
            None => k,
        }
    }
    async fn shade(&self, f: impl Fragment) {
        let i = f.primitive_id() as usize;
        if !self.seg.passes(i, self.eye) || !self.seg.in_piece(i, f.barycentrics()) {
            f.discard();
            return;
        }
        let c = common::unpack_color(common::prim_color_packed(self.seg.tri[i]));
        let a = self.alpha;
        let base = f.pixel_index() * 4;
        if self.interlock.is_some() {
            f.interlock_begin().await;
        }
        for (ch, cv) in (0u32..).zip(&c[..3]) {
            let d = f.load(self.color, base + ch).await;
            f.store(self.color, base + ch, cv * a + d * (1.0 - a)).await;
        }
        let d = f.load(self.color, base + 3).await;
        f.store(self.color, base + 3, a + d * (1.0 - a)).await;
        if self.interlock.is_some() {
            f.interlock_end().await;
        }
    }
}

/// Which run-time option.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    Fragment,
    Vertex,
    Ssbo,
    SsboInterlock,
}

/// A presorted-lists algorithm.
pub struct PresortedAlgo(pub Variant);

/// Every presorted algorithm.
pub fn algorithms() -> Vec<Box<dyn Algorithm>> {
    [
        Variant::Fragment,
        Variant::Vertex,
        Variant::Ssbo,
        Variant::SsboInterlock,
    ]
    .into_iter()
    .map(|v| Box::new(PresortedAlgo(v)) as Box<dyn Algorithm>)
    .collect()
}

const SOURCE: &str = "Chen, Sander, Nehab, Yang, Hu: Depth-Presorted Triangle Lists, sections 4-5";

impl Algorithm for PresortedAlgo {
    fn info(&self) -> AlgoInfo {
        let (name, summary, passes, memory, hazard) = match self.0 {
            Variant::Fragment => (
                "presorted",
                "depth-presorted triangle lists: the viewpoint's segment, half-space test per fragment (every copy, no depth test), fixed-function over in API order",
                "1 geometry (after off-line preprocessing)",
                "16 bytes (RGBA32F colour)",
                HazardClass::HazardFree,
            ),
            Variant::Vertex => (
                "presorted-vs",
                "depth-presorted triangle lists, half-space test in the vertex stage (failing triangles moved to the viewpoint)",
                "1 geometry (after off-line preprocessing)",
                "16 bytes (RGBA32F colour)",
                HazardClass::HazardFree,
            ),
            Variant::Ssbo => (
                "presorted-ssbo",
                "depth-presorted triangle lists blended by the kernel: plain read-blend-write of a buffer (races)",
                "1 geometry (after off-line preprocessing)",
                "16 bytes",
                HazardClass::HazardProne,
            ),
            Variant::SsboInterlock => (
                "presorted-ssbo-interlock",
                "presorted-ssbo inside ordered pixel interlock: the kernel's blend in primitive order",
                "1 geometry (after off-line preprocessing)",
                "16 bytes",
                HazardClass::NeedsInterlock,
            ),
        };
        AlgoInfo {
            name,
            family: "presorted",
            summary,
            source: SOURCE,
            passes,
            memory,
            hazard,
            capacity: Capacity::Image,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let prep = prepared(frame.mesh, params, exec.threads)?;
        let eye = eye_of(frame.view_proj)?;
        let k = prep
            .lists
            .locate(eye)
            .map_err(|e| AlgoError::Invalid(e.to_string()))?;
        let seg = &prep.segments[k];
        let eye32 = eye.as_vec3();
        let sub = Frame {
            mesh: &seg.mesh,
            ..*frame
        };
        let bg = params.background;
        let mut device = common::fresh(exec);
        let (report, image, storage) = match self.0 {
            Variant::Fragment | Variant::Vertex => {
                let mut fb = framebuffer(&sub, SampleCount::X1, &[Format::RGBA32F])?;
                fb.clear_color(0, [bg[0].to_bits(), bg[1].to_bits(), bg[2].to_bits(), 0]);
                let mut state = capture_state();
                // Selection by the planes alone (module docs): no depth test.
                state.fragment.depth = DepthState {
                    test: false,
                    func: CompareFunc::Always,
                    write: false,
                };
                let mut t = TargetState::new(Format::RGBA32F);
                t.blend = Some(fragrace_emu::BlendState::over());
                state.fragment.targets = vec![t];
                let report = if self.0 == Variant::Fragment {
                    let kernel = SelectKernel {
                        seg,
                        eye: eye32,
                        alpha: params.alpha,
                    };
                    common::geometry_pass(&device, &mut fb, &sub, &state, &kernel, exec)?
                } else {
                    let moved = vertex_stage(seg, eye32);
                    let vs_frame = Frame {
                        mesh: &moved,
                        ..*frame
                    };
                    let kernel = ColorKernel {
                        seg,
                        alpha: params.alpha,
                    };
                    common::geometry_pass(&device, &mut fb, &vs_frame, &state, &kernel, exec)?
                };
                let img = fb.image(0);
                let image: Vec<[f32; 4]> =
                    img.texels.iter().map(|t| t.map(f32::from_bits)).collect();
                (report, image, pixels(frame) as u64 * 16)
            }
            Variant::Ssbo | Variant::SsboInterlock => {
                let n = pixels(frame);
                let color = device.buffer::<f32>("presorted-color", n as u64 * 4)?;
                let init: Vec<f32> = (0..n).flat_map(|_| [bg[0], bg[1], bg[2], 0.0]).collect();
                device.memory.write(color, 0, &init)?;
                let mut fb = framebuffer(&sub, SampleCount::X1, &[])?;
                let kernel = SsboKernel {
                    seg,
                    eye: eye32,
                    alpha: params.alpha,
                    color,
                    interlock: (self.0 == Variant::SsboInterlock).then_some(InterlockMode::ORDERED),
                };
                let report =
                    common::geometry_pass(&device, &mut fb, &sub, &capture_state(), &kernel, exec)?;
                let v = device.memory.read(color)?;
                let image = v
                    .chunks_exact(4)
                    .map(|c| [c[0], c[1], c[2], c[3]])
                    .collect();
                (report, image, device.memory.bytes())
            }
        };
        let mut checks = vec![selection_check(seg, eye32, &prep.lists, k)];
        // Each input triangle drawn exactly once: the fragments blended (past the selection
        // and the piece clips) are exactly those of the input mesh (an extra pass, not in
        // the report).
        let blended = match self.0 {
            Variant::Fragment | Variant::Vertex => report.stats.samples_passed,
            Variant::Ssbo | Variant::SsboInterlock => {
                report.stats.shaded.saturating_sub(report.stats.discarded)
            }
        };
        let input = input_fragments(frame, exec)?.stats.fragments_generated;
        checks.push(Check::new(
            "every input triangle rasterized exactly once (fragments blended = fragments of the input mesh)",
            blended == input,
            format!("{blended} fragments blended, the input mesh makes {input}"),
        ));
        checks.push(Check::new(
            "viewpoint outside the bounding polyhedron (partition picked by the CPU)",
            true,
            format!(
                "partition {k} of {}, {} instances in its segment",
                prep.lists.dirs.len(),
                seg.tri.len()
            ),
        ));
        Ok(AlgoResult {
            image: Some(image),
            report,
            checks,
            storage_bytes: storage,
            ..Default::default()
        })
    }

    fn self_check(&self, result: &mut AlgoResult, exec: &ExecConfig) {
        let _ = (result, exec);
    }
}

/// The vertex stage of `presorted-vs`: three vertices per instance (no sharing); those of
/// an instance failing its test moved to the viewpoint, where the near plane culls them.
pub fn vertex_stage(seg: &SegmentData, eye: Vec3) -> Mesh {
    let mut positions = Vec::with_capacity(seg.mesh.indices.len() * 3);
    for (i, t) in seg.mesh.indices.iter().enumerate() {
        let keep = seg.passes(i, eye);
        for &v in t {
            positions.push(if keep {
                seg.mesh.positions[v as usize]
            } else {
                eye
            });
        }
    }
    let indices = (0..seg.mesh.indices.len() as u32)
        .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
        .collect();
    Mesh {
        positions,
        normals: None,
        indices,
    }
}

/// Host check of the selection: with every copy's exact planes, each piece (each input
/// triangle, unless some were split) has exactly one instance that passes.
fn selection_check(seg: &SegmentData, eye: Vec3, lists: &Presorted, k: usize) -> Check {
    let mut count = vec![0u32; lists.pieces.len()];
    for i in 0..seg.piece.len() {
        if seg.passes(i, eye) {
            count[seg.piece[i] as usize] += 1;
        }
    }
    let bad: Vec<(usize, u32)> = count
        .iter()
        .enumerate()
        .filter(|(_, &c)| c != 1)
        .map(|(t, &c)| (t, c))
        .take(5)
        .collect();
    let what = if lists.is_split() {
        format!(
            "{} triangles as {} pieces (crossing triangles split), segment {k}",
            lists.triangles,
            lists.pieces.len()
        )
    } else {
        format!("{} triangles, segment {k}", lists.triangles)
    };
    Check::new(
        "every input triangle's front or back copy selected exactly once",
        bad.is_empty(),
        if bad.is_empty() {
            what
        } else {
            format!(
                "{} pieces selected other than once, first (piece, copies): {bad:?}; {what}",
                count.iter().filter(|&&c| c != 1).count()
            )
        },
    )
}

/// Fragments the input mesh generates through `frame` (the count a run that draws each
/// triangle exactly once must blend).
pub fn input_fragments(frame: &Frame<'_>, exec: &ExecConfig) -> Result<PassReport, AlgoError> {
    let device = common::fresh(exec);
    let mut fb = framebuffer(frame, SampleCount::X1, &[])?;
    struct Nop;
    impl FragmentKernel for Nop {
        fn info(&self) -> KernelInfo {
            KernelInfo::new("presorted-count").without_interpolants()
        }
        async fn shade(&self, _f: impl Fragment) {}
    }
    common::geometry_pass(&device, &mut fb, frame, &capture_state(), &Nop, exec)
}
