//! What an algorithm is, what it is given and what it returns.

use fragrace_emu::{Device, ExecConfig, Mesh, PassError, PassReport};
use glam::Mat4;

/// The scene as an algorithm sees it: one mesh through one camera, at a resolution.
#[derive(Clone, Copy, Debug)]
pub struct Frame<'m> {
    pub mesh: &'m Mesh,
    /// The scene's objects: ranges of the mesh's triangles, in order (empty: the whole mesh
    /// is one object). Geometry culling ([`Params::geometry_culling`]) draws and culls them
    /// one by one.
    pub objects: &'m [std::ops::Range<u32>],
    pub view_proj: Mat4,
    pub width: u32,
    pub height: u32,
}

/// Tunable parameters shared by the algorithms (each reads the ones it uses).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Params {
    /// k of the k-buffers.
    pub k: u32,
    /// Constant opacity of every fragment in the OIT composite (as the llvmpipe peer).
    pub alpha: f32,
    /// Node pool of the linked lists, in nodes per pixel (`None`: sized exactly from a count
    /// pass, as the llvmpipe peer does).
    pub pool_per_pixel: Option<f32>,
    /// Iteration cap of spinlocks (fragments that give up are dropped, and counted).
    pub spin_cap: u32,
    /// Buckets of the bucket schemes.
    pub buckets: u32,
    /// Fragments per pixel of the fixed-array A-buffer (FAB).
    pub fab_capacity: u32,
    /// Background colour of the composite.
    pub background: [f32; 3],
    /// Occupancy-map culling in front of the capture pass (`--occupancy D`), for the
    /// algorithms that take it ([`Algorithm::takes_occupancy`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occupancy: Option<crate::occupancy::Occupancy>,
    /// Fragment merging: z-thickness and beta (the `merging` family). Left out of case files
    /// when default, so that files of runs that do not merge are as before.
    #[serde(
        default,
        skip_serializing_if = "crate::merging::MergeParams::is_default"
    )]
    pub merge: crate::merging::MergeParams,
    /// Where the bucket schemes (`bdp`, `bdp2`, `adp`) take each pixel's depth range from
    /// (`--range`): the occupancy stage's range pass, run on its own.
    #[serde(default, skip_serializing_if = "is_default_range")]
    pub range: crate::occupancy::RangeSource,
    /// Geometry culling of the multi-pass peelers that take it
    /// ([`Algorithm::takes_geometry_culling`]; `--geometry-culling`): objects completely
    /// peeled are culled by occlusion queries and conditional rendering.
    #[serde(
        default,
        skip_serializing_if = "crate::peeling::GeometryCulling::is_off"
    )]
    pub geometry_culling: crate::peeling::GeometryCulling,
    /// Depth-presorted triangle lists (the `presorted` family): the file `fragrace presort`
    /// wrote for the mesh (`--presorted FILE`); without it the mesh is preprocessed on first
    /// use.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub presorted: Option<std::path::PathBuf>,
}

fn is_default_range(r: &crate::occupancy::RangeSource) -> bool {
    *r == crate::occupancy::RangeSource::default()
}

impl Default for Params {
    fn default() -> Self {
        Params {
            k: 8,
            alpha: 0.3,
            pool_per_pixel: None,
            spin_cap: 1024,
            buckets: 5,
            fab_capacity: 64,
            background: [1.0, 1.0, 1.0],
            occupancy: None,
            merge: crate::merging::MergeParams::default(),
            range: crate::occupancy::RangeSource::default(),
            geometry_culling: crate::peeling::GeometryCulling::Off,
            presorted: None,
        }
    }
}

/// Whether an algorithm races by design.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HazardClass {
    /// Correct under every interleaving (atomics only where they matter).
    HazardFree,
    /// Races by design: results depend on the interleaving.
    HazardProne,
    /// Correct only with pixel interlock (which it uses).
    NeedsInterlock,
}

impl HazardClass {
    pub fn name(self) -> &'static str {
        match self {
            HazardClass::HazardFree => "hazard-free",
            HazardClass::HazardProne => "hazard-prone",
            HazardClass::NeedsInterlock => "needs-interlock",
        }
    }
}

/// What the algorithm keeps per pixel, for the oracle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Capacity {
    /// Every fragment (A-buffers): compared with all of truth's.
    All,
    /// The k nearest (k-buffers): compared with truth's k nearest depths.
    KNearest,
    /// Per-pixel fragment counts only.
    Count,
    /// The nearest surface only.
    Nearest,
    /// Only an image (approximations such as weighted blended OIT): compared as images.
    Image,
}

/// Declared properties of an algorithm.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AlgoInfo {
    pub name: &'static str,
    pub family: &'static str,
    pub summary: &'static str,
    /// Paper and section it comes from.
    pub source: &'static str,
    /// Passes, as a formula (e.g. "1 geometry + 1 full-screen").
    pub passes: &'static str,
    /// Memory per pixel, as in Table 1 of the depth-fighting paper (e.g. "4 + 12 n bytes").
    pub memory: &'static str,
    pub hazard: HazardClass,
    pub capacity: Capacity,
}

/// Fragments kept per pixel, compressed-row: pixel p's fragments are
/// `frags[offsets[p] .. offsets[p + 1]]`, in the order the algorithm resolves them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Capture {
    pub width: u32,
    pub height: u32,
    pub offsets: Vec<u32>,
    pub frags: Vec<CapturedFrag>,
}

/// One captured fragment.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CapturedFrag {
    pub depth: f32,
    /// Primitive id, or `u32::MAX` when the algorithm does not keep it.
    pub prim: u32,
}

impl CapturedFrag {
    /// A fragment from the two words the kernels store it as: the depth's f32 bits and the
    /// primitive id (list nodes, k-buffer slots, SRAB samples all keep this pair).
    pub fn from_bits(depth_bits: u32, prim: u32) -> CapturedFrag {
        CapturedFrag {
            depth: f32::from_bits(depth_bits),
            prim,
        }
    }
}

impl Capture {
    /// Builds a capture from per-pixel lists.
    pub fn from_lists(
        width: u32,
        height: u32,
        lists: impl IntoIterator<Item = Vec<CapturedFrag>>,
    ) -> Capture {
        let mut offsets = vec![0u32];
        let mut frags = Vec::new();
        for l in lists {
            frags.extend(l);
            offsets.push(frags.len() as u32);
        }
        Capture {
            width,
            height,
            offsets,
            frags,
        }
    }
    pub fn pixel(&self, p: usize) -> &[CapturedFrag] {
        &self.frags[self.offsets[p] as usize..self.offsets[p + 1] as usize]
    }
    pub fn pixels(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
}

/// One invariant checked on a run.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Check {
    pub name: String,
    pub passed: bool,
    /// What was found (counts, the first offending pixel, ...).
    pub detail: String,
}

impl Check {
    pub fn new(name: impl Into<String>, passed: bool, detail: impl Into<String>) -> Check {
        Check {
            name: name.into(),
            passed,
            detail: detail.into(),
        }
    }

    /// "every fragment shaded, none faulted": a pass shaded each of the fragments it
    /// generated and the run reported no fault.
    pub fn all_shaded(stats: &fragrace_emu::Stats, faults: usize) -> Check {
        Check::new(
            "every fragment shaded, none faulted",
            stats.shaded == stats.fragments_generated && faults == 0,
            format!(
                "generated {}, shaded {}, faults {faults}",
                stats.fragments_generated, stats.shaded
            ),
        )
    }

    /// "image finite": no channel of a resolved image is NaN or infinite.
    pub fn image_finite(image: &[[f32; 4]]) -> Check {
        let bad = image.iter().position(|v| v.iter().any(|c| !c.is_finite()));
        Check::new(
            "image finite",
            bad.is_none(),
            format!("first non-finite pixel {bad:?}"),
        )
    }
}

/// What one run of an algorithm produced.
#[derive(Debug, Default)]
pub struct AlgoResult {
    /// What was kept per pixel (for `Capacity::All`, `KNearest`, `Nearest`).
    pub capture: Option<Capture>,
    /// Per-pixel counts (for `Capacity::Count`), row-major, top row first.
    pub counts: Option<fragrace_emu::Values<u32>>,
    /// The resolved image (RGBA, row-major, top row first), e.g. the OIT composite.
    pub image: Option<Vec<[f32; 4]>>,
    /// All passes' reports merged.
    pub report: PassReport,
    /// Invariants checked on this run.
    pub checks: Vec<Check>,
    /// Fragments generated that the algorithm could not keep (pool or array overflow,
    /// spinlock give-ups, stencil routing beyond the samples), counted by the algorithm.
    pub dropped: u64,
    /// Storage the algorithm allocated (buffers and its render targets), in bytes.
    pub storage_bytes: u64,
    /// What occupancy culling did, when it ran ([`Params::occupancy`]).
    pub culling: Option<crate::occupancy::CullSummary>,
    /// What geometry culling did, when it ran ([`Params::geometry_culling`]): objects drawn
    /// and occlusion queries issued per iteration.
    pub geometry_culling: Option<crate::peeling::ObjectCulling>,
    /// Bucket schemes only: per pixel (row-major), the fragments that lost their bucket to
    /// another fragment routed to the same one (deterministic, not races).
    pub collisions: Option<Vec<u32>>,
    /// What [`Algorithm::run_frame`] left for [`Algorithm::self_check`] (readbacks and the
    /// checks that walk them); `None` once done, or when the frame left nothing.
    pub deferred: Option<Deferred>,
}

/// The host work a frame leaves for [`Algorithm::self_check`]: reading whole buffers and
/// the resolve target back, rebuilding the capture from them, and the invariants checked on
/// it (the llvmpipe peer reads back and checks untimed too). It owns what it reads (the
/// device and its framebuffer), and fills in the result's capture, image and checks.
pub struct Deferred(Box<DeferredWork>);

/// The work of a [`Deferred`].
type DeferredWork = dyn FnOnce(&mut AlgoResult) -> Result<(), AlgoError> + Send;

impl Deferred {
    pub fn new(
        work: impl FnOnce(&mut AlgoResult) -> Result<(), AlgoError> + Send + 'static,
    ) -> Self {
        Deferred(Box::new(work))
    }

    /// Does the work on `result`; an error (a buffer that cannot be read back) is a failed
    /// check, named after the work.
    pub fn run(self, result: &mut AlgoResult) {
        if let Err(e) = (self.0)(result) {
            result.checks.push(Check::new(
                "the self-checks read the buffers back",
                false,
                e.to_string(),
            ));
        }
    }
}

impl std::fmt::Debug for Deferred {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Deferred(..)")
    }
}

/// Why an algorithm could not run.
#[derive(Debug, thiserror::Error)]
pub enum AlgoError {
    #[error(transparent)]
    Pass(#[from] PassError),
    #[error(transparent)]
    Memory(#[from] fragrace_emu::memory::MemoryError),
    #[error(transparent)]
    Framebuffer(#[from] fragrace_emu::framebuffer::FramebufferError),
    #[error("{0}")]
    Invalid(String),
}

/// A shared tunable parameter of [`Params`] that some algorithms read and others do not
/// ([`Algorithm::reads`]): the command line refuses it for an algorithm that does not.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Param {
    /// [`Params::k`] (`--k`).
    K,
    /// [`Params::spin_cap`] (`--spin-cap`).
    SpinCap,
}

impl Param {
    /// The command-line option.
    pub fn option(self) -> &'static str {
        match self {
            Param::K => "k",
            Param::SpinCap => "spin-cap",
        }
    }
}

/// A multi-fragment algorithm.
pub trait Algorithm: Send + Sync {
    fn info(&self) -> AlgoInfo;

    /// Whether the algorithm reads `p`. By default it reads `k` (it keeps or peels k
    /// fragments per pixel) and not `spin_cap` (it has no spin lock); an algorithm for which
    /// this is wrong says so here (`tests/params.rs` holds each declaration against runs
    /// with different values).
    fn reads(&self, p: Param) -> bool {
        p == Param::K
    }

    /// Whether the algorithm runs its capture pass behind occupancy culling when
    /// [`Params::occupancy`] asks for it (the k-buffers whose capture is one geometry pass).
    /// Others refuse the parameter (the CLI checks this before running).
    fn takes_occupancy(&self) -> bool {
        false
    }

    /// Whether the algorithm culls completely peeled objects when
    /// [`Params::geometry_culling`] asks for it (every multi-pass peeler, front-to-back and
    /// dual). Others refuse the parameter.
    fn takes_geometry_culling(&self) -> bool {
        false
    }

    /// Whether the algorithm starts from a per-pixel depth range ([`Params::range`], the
    /// bucket schemes); others ignore the parameter (the CLI refuses `--range` for them
    /// without occupancy culling).
    fn takes_range(&self) -> bool {
        false
    }

    /// The frame: every pass of the algorithm on a fresh device, shaded with `exec`, and the
    /// resolve, without the self-checks that read a whole buffer back only to check it (the
    /// frame as the llvmpipe peer times it: clears, passes, resolve; its own checks run
    /// untimed). An algorithm whose checks are cheap next to its passes runs them here; one
    /// whose checks read a buffer back leaves them as [`AlgoResult::deferred`] work for
    /// [`Algorithm::self_check`]. `fragrace bench` times this and the checks apart.
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError>;

    /// The frame ([`Algorithm::run_frame`]) and then every check of the algorithm's
    /// invariants ([`Algorithm::self_check`], [`AlgoResult::checks`]): what `render`,
    /// `check` and the oracle run.
    fn run(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut r = self.run_frame(frame, params, exec)?;
        self.self_check(&mut r, exec);
        Ok(r)
    }

    /// Completes a result of [`Algorithm::run_frame`] with the checks it left out (and what
    /// they find, as [`AlgoResult::dropped`]). By default the result's
    /// [`AlgoResult::deferred`] work, if any.
    fn self_check(&self, result: &mut AlgoResult, exec: &ExecConfig) {
        let _ = exec;
        if let Some(work) = result.deferred.take() {
            work.run(result);
        }
    }
}

/// Runs with a fresh device (helper for implementations).
pub fn fresh_device() -> Device {
    Device::new()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::*;

    /// The algorithms whose frame defers its readbacks: `run` is exactly the frame followed
    /// by `self_check`, and the frame alone reads nothing back.
    #[test]
    fn a_deferred_frame_then_its_self_check_is_run() {
        let mesh = layers();
        let f = frame_sized(&mesh, 24, 20);
        let exec = ExecConfig::ordered();
        let params = Params::default();
        for name in [
            "ll",
            "kb-rmw",
            "kb-atomic32",
            "kb-atomic64",
            "kb-interlock",
            "kb-interlock-unordered",
            "kplus",
            "kplus-heap",
            "skb-ofm",
            "skb-ofm-unordered",
            "kb-ofm",
            "dfb-sfm",
            "wboit",
            "srab",
        ] {
            let algo = crate::algorithm(name).unwrap();
            let whole = algo.run(&f, &params, &exec).unwrap();
            let mut split = algo.run_frame(&f, &params, &exec).unwrap();
            assert!(
                split.checks.is_empty() && split.capture.is_none() && split.image.is_none(),
                "{name}: the frame alone reads nothing back"
            );
            assert!(split.deferred.is_some(), "{name}");
            algo.self_check(&mut split, &exec);
            assert!(split.deferred.is_none(), "{name}: done once");
            assert_eq!(split.capture, whole.capture, "{name}");
            assert_eq!(split.image, whole.image, "{name}");
            assert_eq!(split.dropped, whole.dropped, "{name}");
            assert_eq!(split.storage_bytes, whole.storage_bytes, "{name}");
            let checks = |r: &AlgoResult| {
                r.checks
                    .iter()
                    .map(|c| (c.name.clone(), c.passed, c.detail.clone()))
                    .collect::<Vec<_>>()
            };
            assert_eq!(checks(&split), checks(&whole), "{name}");
            assert!(
                !whole.checks.is_empty() && whole.checks.iter().all(|c| c.passed),
                "{name}: {:?}",
                whole.checks
            );
        }
    }
}
