//! Depth peeling: multi-pass algorithms that extract the fragments of every pixel layer by
//! layer, each geometry pass peeling the next layer behind the one before (DUAL: the next
//! one at each end of the remaining depth range).
//!
//! The classic front-to-back peeling (F2B, Everitt 2001, \[12\] of the depth-fighting paper)
//! and its two-pass form F2B2 (section 4), the depth-fighting paper's coplanarity-aware
//! variants of it (section 3.1: F2B-2P, Algorithm 1; F2B-3P; F2B-LL, Algorithm 2; section
//! 3.2: F2B-B, Algorithm 3, with FAB, KB and atomic KB storage), and dual depth peeling (DUAL,
//! Bavoil & Myers 2008, \[13\] there, section 3.1.2) with its variants DUAL-2P, DUAL-LL and
//! DUAL-B. They share the peel loop's shape, which lives here:
//!
//! - every iteration is one to three geometry passes; the front-to-back peelers' host loop
//!   ends when the occlusion query of the last depth or count pass (samples passed) is zero,
//!   or after `k` iterations (the paper avoids reading the query back with conditional
//!   rendering, section 3.3; here the read-back costs nothing, so the loop reads it); the
//!   dual peelers end when the min-max target read back holds no range; with geometry
//!   culling (`culling.rs`, `Params::geometry_culling`) every peeler draws the scene object
//!   by object under conditional rendering;
//! - the fragments extracted are gathered into per-pixel lists on the host (after each
//!   iteration, or by walking the linked lists at the end), sorted by (depth, primitive),
//!   and the front-to-back peelers keep the first `k`;
//! - the image is the front-to-back composite of the kept fragments (what the paper's
//!   blend-under accumulation of each peeled layer computes), by primitive colour at the
//!   constant opacity `params.alpha`, as every other algorithm's resolve.
//!
//! **How many layers.** As the k-buffers keep the `k` nearest fragments, the front-to-back
//! peelers peel at most `k` iterations (the paper's "maximum number of iterations set by
//! the user") and keep the first `k` fragments they extracted, which the oracle compares
//! with the true `k` nearest (`Capacity::KNearest`). `--k` large enough peels every layer.
//! DUAL peels from both ends, so a cap would keep layers that are not the nearest: it peels
//! every layer (`Capacity::All`).
//!
//! **Hazards.** Classic peeling needs no shared memory: the depth test, blending and the
//! images read back from earlier passes are fixed-function and API ordered, so every
//! executor gives the same result. What it loses is by design: F2B discards every fragment
//! at the depth of the layer it peeled last, so coplanar fragments collapse into one
//! (robustness ratio below 1 where the scene has coplanar fragments: the depth-fighting
//! paper's motivation, section 1); DUAL loses them at both ends of its range. Both count the
//! lost fragments with one atomic counter (`AlgoResult::dropped`). F2B-LL adds a per-pixel
//! linked list with atomics.

crate::registry::family! {
    f2b,
    f2b2,
    f2b2p,
    f2b3p,
    f2bll,
    f2bb,
    dual,
    dual2p,
    dualb,
    dualll,
}

mod culling;

use fragrace_emu::{Format, Framebuffer, Image, SampleCount};

use crate::algo::{AlgoError, AlgoResult, Capture, CapturedFrag, Check, Frame, Params};
use crate::common::{self, composite_frags, depth_order, pixels};

pub use culling::{CullIteration, GeometryCulling, ObjectCulling};

/// Most layers a peeler may be asked for (k), so that a typo cannot ask for billions of
/// geometry passes.
pub const MAX_LAYERS: u32 = 1 << 16;

/// The layers of a peel run: what each pixel's iterations extracted, in order.
pub(super) struct Peeled<'a> {
    pub frame: Frame<'a>,
    pub params: &'a Params,
    /// Iterations allowed (`params.k`).
    pub k: u32,
    pub lists: Vec<Vec<CapturedFrag>>,
    /// Iterations run.
    pub iterations: u32,
}

impl<'a> Peeled<'a> {
    /// A peel of every layer (DUAL, DUAL-LL): no cap on the lists.
    pub fn unbounded(frame: &Frame<'a>, params: &'a Params) -> Peeled<'a> {
        Peeled {
            frame: *frame,
            params,
            k: u32::MAX,
            lists: vec![Vec::new(); pixels(frame)],
            iterations: 0,
        }
    }

    pub fn new(frame: &Frame<'a>, params: &'a Params) -> Result<Peeled<'a>, AlgoError> {
        if params.k == 0 || params.k > MAX_LAYERS {
            return Err(AlgoError::Invalid(format!(
                "k = {} layers is outside 1..={MAX_LAYERS}",
                params.k
            )));
        }
        Ok(Peeled {
            frame: *frame,
            params,
            k: params.k,
            lists: vec![Vec::new(); pixels(frame)],
            iterations: 0,
        })
    }

    /// A single-sample framebuffer of the frame with `formats` as its targets.
    pub fn framebuffer(&self, formats: &[Format]) -> Result<Framebuffer, AlgoError> {
        common::framebuffer(&self.frame, SampleCount::X1, formats)
    }

    /// The per-pixel lists truncated to the first `k` extracted, the composite image, and
    /// the result. `bytes_per_pixel`: the targets and images the passes used (the device's
    /// buffers are added).
    pub fn finish(
        self,
        report: fragrace_emu::PassReport,
        mut checks: Vec<Check>,
        device_bytes: u64,
        bytes_per_pixel: u64,
    ) -> AlgoResult {
        let k = self.k as usize;
        let mut beyond = 0u64;
        let lists: Vec<Vec<CapturedFrag>> = self
            .lists
            .into_iter()
            .map(|mut l| {
                // Extraction order is front to back, but F2B-2P takes a coplanar group's
                // ids from both ends: the truth's order within a depth is by primitive.
                l.sort_by(depth_order);
                beyond += l.len().saturating_sub(k) as u64;
                l.truncate(k);
                l
            })
            .collect();
        let alpha = self.params.alpha;
        let background = self.params.background;
        let image = lists
            .iter()
            .map(|l| composite_frags(l, alpha, background))
            .collect();
        let detail = if self.k == u32::MAX {
            format!("{} iterations, every layer", self.iterations)
        } else {
            format!(
                "{} iterations of at most k = {}; {beyond} fragments extracted beyond the k-th of their pixel",
                self.iterations, self.k
            )
        };
        checks.push(Check::new("iterations (informational)", true, detail));
        let n = lists.len() as u64;
        AlgoResult {
            capture: Some(Capture::from_lists(
                self.frame.width,
                self.frame.height,
                lists,
            )),
            image: Some(image),
            report,
            checks,
            storage_bytes: device_bytes + n * bytes_per_pixel,
            ..Default::default()
        }
    }
}

/// When a peel ended because nothing was left (not because of `k`), every fragment the
/// scene generated was peeled, or counted as lost: `accounted` must be `generated`.
pub(super) fn conservation(exhausted: bool, accounted: u64, generated: u64) -> Check {
    Check::new(
        "a peel run to the end accounts for every fragment (peeled or counted lost)",
        !exhausted || accounted == generated,
        if exhausted {
            format!("{accounted} accounted for of {generated} generated")
        } else {
            format!("not run to the end (k reached); {accounted} of {generated} so far")
        },
    )
}

/// The id-range peelers' extraction (F2B-2P, F2B-3P): each iteration takes, per pixel, the
/// fragments with the smallest and the largest unpeeled id of the layer, as the count pass
/// chose them and the extract pass found them, and tallies what the checks need.
#[derive(Default)]
pub(super) struct IdExtraction {
    /// Ids whose fragment was not at the layer's depth.
    not_found: u64,
    /// Extractions in front of an earlier one of their pixel.
    backwards: u64,
}

impl IdExtraction {
    /// Appends to `list` the extracted fragments of a pixel at layer depth `d`, given its
    /// count pass texel `(-id_min, id_max, _, count)` and its extract texel `(depth of
    /// id_min, depth of id_max)`. Returns the count.
    pub fn take(
        &mut self,
        list: &mut Vec<CapturedFrag>,
        d: f32,
        ids: [f32; 4],
        got: [f32; 4],
    ) -> f32 {
        let [neg_min, max, _, n] = ids;
        let mut push = |depth: f32, id: f32| {
            self.not_found += u64::from(depth != d);
            self.backwards += u64::from(list.last().is_some_and(|l| l.depth > depth));
            list.push(CapturedFrag {
                depth,
                prim: id as u32,
            });
        };
        if n >= 1.0 {
            push(got[0], -neg_min);
        }
        if n >= 2.0 {
            push(got[1], max);
        }
        n
    }

    /// The checks of an id-range peel; `stalled`: layers left while fragments remained.
    pub fn checks(
        &self,
        lists: &[Vec<CapturedFrag>],
        exhausted: bool,
        generated: u64,
        stalled: u64,
    ) -> Vec<Check> {
        let twice: u64 = lists
            .iter()
            .map(|l| {
                let mut v: Vec<(u32, u32)> =
                    l.iter().map(|f| (f.depth.to_bits(), f.prim)).collect();
                v.sort_unstable();
                v.windows(2).filter(|w| w[0] == w[1]).count() as u64
            })
            .sum();
        let extracted: u64 = lists.iter().map(|l| l.len() as u64).sum();
        vec![
            conservation(exhausted, extracted, generated),
            Check::new(
                "every extracted fragment is found at its layer's depth",
                self.not_found == 0,
                format!("{} ids without their fragment", self.not_found),
            ),
            Check::new(
                "no fragment is extracted twice",
                twice == 0,
                format!("{twice} repeats"),
            ),
            Check::new(
                "layers never go backwards, and stay while fragments are left",
                self.backwards == 0 && stalled == 0,
                format!(
                    "{} extractions in front of an earlier one, {stalled} layers left early",
                    self.backwards
                ),
            ),
        ]
    }
}

/// Texel `p` (row-major pixel index) of a single-sample image as floats.
pub(super) fn texel_f32(image: &Image, p: usize) -> [f32; 4] {
    image.texels[p].map(f32::from_bits)
}

/// Runs a peeler that loses coplanar fragments by design on the 16-quad scene under every
/// executor: every check passes, the loss shows (errors, `R_h < 1`) and is counted in
/// `dropped`, and the error pixels are the same everywhere (fixed-function, API ordered).
/// Returns each run's result and metrics for further assertions.
#[cfg(test)]
pub(super) fn assert_same_loss_everywhere(
    algo: &dyn crate::algo::Algorithm,
) -> Vec<(String, AlgoResult, crate::oracle::Metrics)> {
    use crate::testing::{executors, frame, quads, run};
    let mesh = quads(16);
    let f = frame(&mesh, 16);
    let mut baseline: Option<Vec<bool>> = None;
    let mut runs = Vec::new();
    for (what, exec) in executors(1) {
        let (r, m) = run(algo, &f, &Params::default(), &exec);
        for c in &r.checks {
            assert!(c.passed, "{what}: {}: {}", c.name, c.detail);
        }
        assert!(m.error_pixels > 0 && m.robustness < 1.0, "{what}: {m:?}");
        assert!(
            r.dropped > 0,
            "{what}: the coplanar fragments lost are counted"
        );
        let b = baseline.get_or_insert_with(|| m.error_mask.clone());
        assert_eq!(
            *b, m.error_mask,
            "{what}: the loss is the same under every executor"
        );
        runs.push((what, r, m));
    }
    runs
}

/// Primitive ids travel through blended float targets as float values (MAX blending works
/// on floats, as on the GPU the papers target): exact below 2^24. (F2B, whose target is not
/// blended, stores the id's bits instead.)
pub(super) fn check_ids_fit_floats(frame: &Frame<'_>) -> Result<(), AlgoError> {
    let prims = frame.mesh.indices.len() as u64;
    if prims > 1 << 24 {
        return Err(AlgoError::Invalid(format!(
            "{prims} primitives: the ids do not fit the 24-bit mantissa of the float targets"
        )));
    }
    Ok(())
}
