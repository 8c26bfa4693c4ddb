//! Occupancy-map fragment culling in front of a k-buffer (Vasilakis and Papaioannou,
//! "Improving k-buffer methods via occupancy maps", Eurographics 2015 short papers: section
//! 2, Figure 3, Lemma 2.1; the occupancy-culling seed).
//!
//! Knowing the depth of the k-th fragment of a pixel would let a k-buffer insert exactly the
//! k nearest fragments and early-z-cull the rest. The stage approximates that depth from
//! above with four passes before the base k-buffer's own capture (the paper's Figure 3):
//!
//! 1. **range** ([`range`]): the per-pixel depth range `[zn, zf]`, from the scene itself
//!    (`exact`: atomic min and max of every fragment's depth), or from a bounding volume
//!    rasterized as geometry (`bbox`, the mesh's axis-aligned box; `hull`, its convex hull);
//! 2. **clear** of the occupancy map, `d` 32-bit words per pixel;
//! 3. **fill** ([`passes::Fill`]): each fragment sets bit `j` of its pixel's map, `j` its
//!    sub-interval among `S = 32 d` uniform ones, with an atomic OR (or, for the
//!    hazard-prone variant, a plain read, OR and write back);
//! 4. **count** ([`passes::Count`], full screen): Kernighan's loop finds the sub-interval
//!    holding the k-th set bit and writes its upper end to the depth buffer; with fewer
//!    than k bits set nothing is culled.
//!
//! The base algorithm then runs its capture pass (the **peel** pass) with an early `LEQUAL`
//! depth test against that bound ([`Culling::peel_state`]), so fragments beyond it are never
//! shaded. **Lemma 2.1**: the k nearest fragments of every pixel pass, because the k-th set
//! bit lies at or after the sub-interval of the k-th nearest fragment (each set bit stands
//! for at least one fragment). The oracle checks it on every culled run
//! (`lemma_2_1_violations`).
//!
//! A racy fill only *loses* bits: every value a plain store writes is the OR of bits that
//! some fragment really set, so the map holds a subset of the true bits, and with fewer bits
//! the k-th one lies farther away. Lost bits make the bound farther (less culling), never
//! nearer: the race is real (the detector reports it on the map's words) but cannot break
//! Lemma 2.1 (test `lemma_2_1_holds_and_lost_bits_only_move_the_bound_farther`).
//!
//! This module knows no k-buffer: it fills a framebuffer's depth buffer and hands back a
//! pass state. Nothing in it depends on which algorithm runs the peel pass.

pub mod bits;
pub mod hull;
pub(crate) mod passes;
pub mod range;

use fragrace_emu::{
    CompareFunc, DepthState, Device, EarlyTests, ExecConfig, Framebuffer, PassReport, PassState,
};

use crate::algo::{AlgoError, Frame, Params};

/// Sub-interval words per pixel, at most (S = 2048 sub-intervals).
pub const MAX_D: u32 = 64;

/// How the per-pixel depth range is found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RangeSource {
    /// Nearest and farthest fragment of the scene itself (a geometry pass of the scene).
    #[default]
    Exact,
    /// The mesh's axis-aligned bounding box (12 triangles).
    Bbox,
    /// The mesh's convex hull, built on the host.
    Hull,
}

impl RangeSource {
    pub fn name(self) -> &'static str {
        match self {
            RangeSource::Exact => "exact",
            RangeSource::Bbox => "bbox",
            RangeSource::Hull => "hull",
        }
    }
}

impl std::str::FromStr for RangeSource {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "exact" => Ok(RangeSource::Exact),
            "bbox" => Ok(RangeSource::Bbox),
            "hull" => Ok(RangeSource::Hull),
            other => Err(format!(
                "unknown depth range `{other}`: expected exact, bbox or hull"
            )),
        }
    }
}

/// How the fill pass sets its bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FillMode {
    /// `atomicOr` (the paper's "atomic operations").
    #[default]
    Atomic,
    /// Plain load, OR, plain store: racy by design (bits are lost).
    Plain,
}

impl FillMode {
    pub fn name(self) -> &'static str {
        match self {
            FillMode::Atomic => "atomic",
            FillMode::Plain => "plain",
        }
    }
}

impl std::str::FromStr for FillMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "atomic" => Ok(FillMode::Atomic),
            "plain" => Ok(FillMode::Plain),
            other => Err(format!(
                "unknown occupancy fill `{other}`: expected atomic or plain"
            )),
        }
    }
}

/// The culling stage's parameters (`--occupancy D --range R --occupancy-fill F`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Occupancy {
    /// Words per pixel: `S = 32 d` sub-intervals, `1 <= d <= 64` and `32 d >= k`.
    pub d: u32,
    #[serde(default)]
    pub range: RangeSource,
    #[serde(default)]
    pub fill: FillMode,
}

impl Occupancy {
    /// Checks `d` against its range and against `k` (the paper's `d >= k / 32`: with fewer
    /// sub-intervals than k, the k-th bit could never be found).
    pub fn validate(&self, k: u32) -> Result<(), AlgoError> {
        if self.d == 0 || self.d > MAX_D {
            return Err(AlgoError::Invalid(format!(
                "--occupancy {}: the occupancy map needs between 1 and {MAX_D} words per pixel",
                self.d
            )));
        }
        if self.d * bits::BITS_PER_WORD < k {
            return Err(AlgoError::Invalid(format!(
                "--occupancy {}: {} sub-intervals cannot hold k = {k} fragments; d must be at \
                 least k / 32 = {} (and at most {MAX_D})",
                self.d,
                self.d * bits::BITS_PER_WORD,
                k.div_ceil(bits::BITS_PER_WORD)
            )));
        }
        Ok(())
    }

    /// Extra storage per pixel, in bytes, that the stage allocates: `d` occupancy words,
    /// near and far depths, and the depth buffer holding the bound.
    pub fn bytes_per_pixel(&self, samples: u32) -> u64 {
        4 * (self.d as u64 + 2 + samples as u64)
    }

    /// The paper's formula (section 3, "Memory Allocation Analysis"): `(d - k + 3)` 32-bit
    /// words per pixel for `d > k`. It counts the near, far and k-th depth textures and the
    /// occupancy buffer, less `k` words that its memory-friendly layout reuses for the
    /// k-buffer's colours; fragrace keeps the map apart, so it stores `d + 3` words.
    pub fn paper_bytes_per_pixel(&self, k: u32) -> i64 {
        4 * (self.d as i64 - k as i64 + 3)
    }
}

/// Where the peel pass tests fragments against the bound.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CullTest {
    /// The early `LEQUAL` depth test ([`Culling::peel_state`]): culled fragments are never
    /// shaded (the paper's hardware culling).
    #[default]
    EarlyDepth,
    /// The capture kernel reads the bound and discards what lies beyond it (the paper's
    /// shader-based culling, `t` in its Figure 5): culled fragments are shaded but store
    /// nothing. For captures whose fixed-function state an early depth test would change
    /// (stencil routing: a stencil test runs before the depth test, so a fragment failing
    /// depth would still step the routing counters).
    Shader,
}

/// One pass of the stage, for reports.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StagePass {
    pub name: &'static str,
    pub wall_ms: f64,
    pub shaded: u64,
    pub fragments: u64,
}

/// What the culling stage did on one run (in [`crate::AlgoResult::culling`]).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct CullSummary {
    pub occupancy: Option<Occupancy>,
    /// Where the peel pass tested the bound.
    pub test: CullTest,
    /// The stage's passes (range, fill, count) and the peel pass.
    pub passes: Vec<StagePass>,
    /// Fragments the peel pass's early depth test killed.
    pub culled_fragments: u64,
    /// Fragments rasterized by the (first) peel pass.
    pub peel_fragments: u64,
    /// Peel passes run behind the bound.
    pub peel_passes: u32,
    /// Bytes per pixel the stage added (map, range, depth buffer).
    pub bytes_per_pixel: u64,
    /// The paper's formula for the same.
    pub paper_bytes_per_pixel: i64,
    /// Per-pixel bound written by the count pass (row-major; [`bits::NO_CULLING`] where
    /// nothing is culled): the oracle checks Lemma 2.1 against it.
    #[serde(skip)]
    pub bounds: Vec<f32>,
    /// Samples per pixel of the peel pass (a multisampled peel tests each sample's depth).
    pub samples: u32,
    /// The stage's own passes (range, fill, count) merged: what culling costs.
    #[serde(skip)]
    pub stage: fragrace_emu::Stats,
    /// Hazards the detector saw in the stage's passes (none with the atomic fill; the lost
    /// bits of the plain one), apart from the algorithm's own.
    pub stage_hazards: fragrace_emu::HazardCounts,
    /// The hottest addresses of the (first) peel pass: the k-buffer's contention behind
    /// the culling, apart from the stage's own map words.
    pub peel_hotspots: Vec<fragrace_emu::stats::Hotspot>,
}

impl CullSummary {
    pub fn culled_fraction(&self) -> f64 {
        if self.peel_fragments == 0 {
            0.0
        } else {
            self.culled_fragments as f64 / self.peel_fragments as f64
        }
    }
}

/// The culling stage of one run: its passes have run, the bound is in the framebuffer's
/// depth buffer.
pub struct Culling {
    occupancy: Occupancy,
    /// Range, fill and count passes, merged.
    pub report: PassReport,
    summary: CullSummary,
}

impl Culling {
    /// Runs range, clear, fill and count into `fb`'s depth buffer when `params.occupancy`
    /// asks for it; `None` otherwise. The peel pass must then draw `frame` into the same
    /// `fb` with [`Culling::peel_state`].
    pub fn prepare(
        device: &mut Device,
        fb: &mut Framebuffer,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<Option<Culling>, AlgoError> {
        let Some(occ) = params.occupancy else {
            return Ok(None);
        };
        occ.validate(params.k)?;
        let n = crate::common::pixels(frame) as u64;
        let mut summary = CullSummary {
            occupancy: Some(occ),
            bytes_per_pixel: occ.bytes_per_pixel(fb.samples.count() as u32),
            paper_bytes_per_pixel: occ.paper_bytes_per_pixel(params.k),
            samples: fb.samples.count() as u32,
            ..Default::default()
        };
        let mut report = PassReport::default();
        let mut note = |name, r: &PassReport| {
            summary.passes.push(StagePass {
                name,
                wall_ms: r.wall.as_secs_f64() * 1e3,
                shaded: r.stats.shaded,
                fragments: r.stats.fragments_generated,
            });
            report.merge(r);
        };

        // 1. Range.
        let (near, far, r) = range::pass(device, frame, occ.range, exec)?;
        note("range", &r);
        // 2. Clear.
        let words = n * occ.d as u64;
        if words > u32::MAX as u64 {
            return Err(AlgoError::Invalid(format!(
                "{n} pixels x d = {} occupancy words exceed the 2^32-word buffer limit",
                occ.d
            )));
        }
        let map = device.buffer::<u32>("occupancy-map", words)?;
        // 3. Fill.
        let fill = passes::Fill {
            map,
            near,
            far,
            d: occ.d,
            mode: occ.fill,
        };
        let r = crate::common::geometry_pass(
            device,
            &mut crate::common::framebuffer(frame, fragrace_emu::SampleCount::X1, &[])?,
            frame,
            &crate::common::capture_state(),
            &fill,
            exec,
        )?;
        note("fill", &r);
        // 4. Count, into the depth buffer.
        let count = passes::Count {
            map,
            near,
            far,
            d: occ.d,
            k: params.k,
        };
        let r = device.fullscreen(fb, &passes::Count::state(), &count, exec)?;
        note("count", &r);
        summary.bounds = (0..frame.height)
            .flat_map(|y| (0..frame.width).map(move |x| (x, y)))
            .map(|(x, y)| fb.depth(x, y, 0))
            .collect();
        Ok(Some(Culling {
            occupancy: occ,
            report,
            summary,
        }))
    }

    pub fn occupancy(&self) -> Occupancy {
        self.occupancy
    }

    /// Each pixel's bound (row-major; [`bits::NO_CULLING`] where nothing is culled), for a
    /// capture kernel that tests it itself ([`CullTest::Shader`]).
    pub fn bounds(&self) -> &[f32] {
        &self.summary.bounds
    }

    /// `base` (the algorithm's own capture state) behind an early `LEQUAL` test against the
    /// bound, without depth writes: the peel pass.
    pub fn peel_state(base: &PassState) -> PassState {
        let mut s = base.clone();
        s.fragment.depth = DepthState {
            test: true,
            func: CompareFunc::LessEqual,
            write: false,
        };
        s.fragment.early = EarlyTests::ForceEarly;
        s
    }

    /// Records a peel pass (an algorithm may peel more than once behind the same bound, as
    /// the 32-bit atomic k-buffer's two capture passes do; the culled count is the first's).
    pub fn add_peel(&mut self, peel: &PassReport) {
        if self.summary.peel_passes == 0 {
            self.summary.culled_fragments = peel.stats.early_culled;
            self.summary.peel_fragments = peel.stats.fragments_generated;
            self.summary.peel_hotspots = peel.stats.hotspots.clone();
        }
        self.summary.peel_passes += 1;
        self.summary.passes.push(StagePass {
            name: "peel",
            wall_ms: peel.wall.as_secs_f64() * 1e3,
            shaded: peel.stats.shaded,
            fragments: peel.stats.fragments_generated,
        });
    }

    /// Records a peel pass whose kernel tested the bound itself ([`CullTest::Shader`]) and
    /// discarded `culled` fragments beyond it.
    pub fn add_shader_peel(&mut self, peel: &PassReport, culled: u64) {
        let first = self.summary.peel_passes == 0;
        self.summary.test = CullTest::Shader;
        self.add_peel(peel);
        if first {
            self.summary.culled_fragments = culled;
        }
    }

    /// The stage's passes (to merge into the run's report) and its summary.
    pub fn finish(mut self) -> (PassReport, CullSummary) {
        self.summary.stage = self.report.stats.clone();
        self.summary.stage_hazards = self.report.hazards;
        (self.report, self.summary)
    }
}
