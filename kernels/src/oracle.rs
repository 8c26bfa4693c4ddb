//! The differential oracle: one comparison of any algorithm's result with [`crate::basic::Truth`]'s
//! on the same frame, and the seeds' metrics.
//!
//! - EPR (bucket-depth-peeling paper, section 5): covered pixels whose result differs from
//!   the truth over covered pixels. "Differs" depends on what the algorithm keeps
//!   ([`Capacity`]): counts must be equal; A-buffers must hold the same multiset of
//!   (depth, primitive); k-buffers the same sorted multiset of depths as the k nearest true
//!   fragments (which of two equal-depth fragments was kept is not an error); `Nearest` the
//!   nearest depth; images any channel off by more than 1/255. An uncovered pixel whose
//!   image is not the background (the composite of nothing) is an error too, counted in
//!   the error pixels (and the image's) though not among the covered ones.
//! - R_h, the robustness ratio (depth-fighting paper, section 3): fragments captured over
//!   fragments the algorithm should have captured (all of them, or `min(k, n)` per pixel).
//! - C_p, the coplanarity probability (depth-fighting paper, Fig. 13): covered pixels with at
//!   least two fragments at exactly the same depth, over covered pixels.
//! - The image metrics ([`ImageMetrics`]), for every algorithm that resolves an image,
//!   whatever it keeps: against the exact composite of the truth's fragments, the per-pixel
//!   maximum channel difference, `image_epr` (covered pixels off by more than 1/255 over
//!   covered pixels, as the bucket-depth-peeling paper's equation 7 counts) and the PSNR.
//!   Algorithms that change the fragment set on purpose (the `merging` family, Kim & Kye,
//!   "Z-Thickness Blending: Effective Fragment Merging for Multi-Fragment Rendering")
//!   are judged by these.

use crate::algo::{AlgoInfo, AlgoResult, Capacity, CapturedFrag, Params};
use crate::common::depth_order;

/// The metrics of one result against the truth.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Metrics {
    pub covered_pixels: u64,
    pub error_pixels: u64,
    pub epr: f64,
    /// Fragments the scene generated (truth's count).
    pub generated: u64,
    /// Fragments the algorithm kept.
    pub captured: u64,
    /// Fragments it should have kept.
    pub expected: u64,
    pub robustness: f64,
    pub coplanarity: f64,
    pub max_depth_complexity: u32,
    /// First pixel (row-major) that differs.
    pub first_error: Option<(u32, u32)>,
    /// Per-pixel error flags, row-major (for heatmaps).
    #[serde(skip)]
    pub error_mask: Vec<bool>,
    /// Occupancy culling only: true fragments among a pixel's k nearest that the culling
    /// bound rejects (Lemma 2.1 of "Improving k-buffer methods via occupancy maps" says
    /// none).
    pub lemma_2_1_violations: Option<u64>,
    /// Occupancy culling only: true fragments beyond their pixel's bound (what the peel
    /// pass's early test must have culled).
    pub culled_truth: Option<u64>,
    /// Occupancy culling only: those fragments per pixel, row-major (for heatmaps).
    #[serde(skip)]
    pub culled_heat: Vec<u32>,
    /// The image against the exact composite of the truth (`None`: the result has no image).
    pub image: Option<ImageMetrics>,
}

/// A resolved image against the exact front-to-back composite of the truth's fragments, over
/// covered pixels (RGB).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ImageMetrics {
    /// Largest channel difference of any covered pixel.
    pub max_diff: f32,
    /// Covered pixels with a channel off by more than [`IMAGE_TOLERANCE`] (or NaN), and
    /// uncovered ones whose image is not the background.
    pub error_pixels: u64,
    /// `error_pixels` over covered pixels.
    pub image_epr: f64,
    /// Mean squared channel error over covered pixels.
    pub mse: f64,
    /// `10 log10(1 / mse)` in dB, peak 1 (infinite for identical images; JSON `null`).
    pub psnr: f64,
    /// Per-pixel maximum channel difference, row-major, 0 where uncovered (heatmaps).
    #[serde(skip)]
    pub diff: Vec<f32>,
}

/// Tolerance of image comparisons (one 8-bit step).
pub const IMAGE_TOLERANCE: f32 = 1.0 / 255.0;

/// Compares `result` of the algorithm described by `info` with `truth` (from
/// [`crate::basic::Truth::capture`] on the same frame).
pub fn compare(
    info: &AlgoInfo,
    result: &AlgoResult,
    truth: &AlgoResult,
    params: &Params,
) -> Metrics {
    let t = truth.capture.as_ref().expect("truth always captures");
    let n = t.pixels();
    let mut m = Metrics {
        error_mask: vec![false; n],
        ..Default::default()
    };
    let k = params.k.max(1) as usize;
    let bounds = result.culling.as_ref().map(|c| &c.bounds[..]);
    if bounds.is_some() {
        m.lemma_2_1_violations = Some(0);
        m.culled_truth = Some(0);
        m.culled_heat = vec![0; n];
    }
    let mut image = result.image.as_ref().map(|_| ImageMetrics {
        diff: vec![0.0; n],
        ..Default::default()
    });
    let mut squared = 0.0f64;
    for p in 0..n {
        let tp = t.pixel(p);
        if let Some(b) = bounds {
            // The peel pass keeps `z <= bound` (early LEQUAL test); truth is sorted, so the
            // culled ones are a suffix and a violation is one among the first k.
            let bound = b.get(p).copied().unwrap_or(f32::NAN);
            let fails = |f: &&CapturedFrag| !crate::occupancy::bits::passes(f.depth, bound);
            let culled = tp.iter().filter(fails).count();
            let violations = tp.iter().take(k).filter(fails).count();
            m.culled_heat[p] = culled as u32;
            *m.culled_truth.as_mut().expect("set above") += culled as u64;
            *m.lemma_2_1_violations.as_mut().expect("set above") += violations as u64;
        }
        if tp.is_empty() {
            // An empty pixel's image is the composite of nothing (the background): this
            // is also what proves the resolves' declared output at pixels no geometry
            // reached (`KernelInfo::with_untouched_output`), which the fused executors
            // write without running the kernel.
            if let Some(img) = result.image.as_ref() {
                let want = crate::common::composite_frags(&[], params.alpha, params.background);
                let got = img.get(p).copied().unwrap_or([f32::NAN; 4]);
                let wrong = (0..3).any(|c| {
                    let d = (got[c] - want[c]).abs();
                    d.is_nan() || d > IMAGE_TOLERANCE
                });
                if wrong {
                    if let Some(im) = image.as_mut() {
                        im.error_pixels += 1;
                        im.diff[p] = f32::INFINITY;
                    }
                    m.error_pixels += 1;
                    m.error_mask[p] = true;
                    m.first_error
                        .get_or_insert(((p as u32) % t.width, (p as u32) / t.width));
                }
            }
            continue;
        }
        if let (Some(im), Some(img)) = (image.as_mut(), result.image.as_ref()) {
            let want = crate::common::composite_frags(tp, params.alpha, params.background);
            let got = img.get(p).copied().unwrap_or([f32::NAN; 4]);
            let mut worst = 0.0f32;
            for c in 0..3 {
                let d = (got[c] - want[c]).abs();
                worst = if d.is_nan() {
                    f32::INFINITY
                } else {
                    worst.max(d)
                };
                squared += if d.is_nan() {
                    1.0
                } else {
                    f64::from(d).powi(2)
                };
            }
            im.diff[p] = worst;
            im.max_diff = im.max_diff.max(worst);
            im.error_pixels += u64::from(worst > IMAGE_TOLERANCE);
        }
        m.covered_pixels += 1;
        m.generated += tp.len() as u64;
        m.max_depth_complexity = m.max_depth_complexity.max(tp.len() as u32);
        if tp.windows(2).any(|w| w[0].depth == w[1].depth) {
            m.coplanarity += 1.0;
        }
        let (wrong, captured, expected) = match info.capacity {
            Capacity::Count => {
                let c = result.counts.as_ref().map(|c| c[p]).unwrap_or(0);
                (c as usize != tp.len(), (c as usize).min(tp.len()), tp.len())
            }
            Capacity::All => {
                let mine = sorted(result, p);
                (!same_frags(&mine, tp), mine.len(), tp.len())
            }
            Capacity::KNearest => {
                let mine = sorted(result, p);
                let want = k.min(tp.len());
                let wrong =
                    mine.len() != want || mine.iter().zip(tp).any(|(a, b)| a.depth != b.depth);
                // Captured = kept depths that are among the true k nearest (multiset
                // intersection of two sorted lists), so a slot filled by the wrong fragment
                // does not count.
                let (mut i, mut j, mut hit) = (0, 0, 0);
                while i < mine.len() && j < want {
                    match mine[i].depth.total_cmp(&tp[j].depth) {
                        std::cmp::Ordering::Equal => {
                            hit += 1;
                            i += 1;
                            j += 1;
                        }
                        std::cmp::Ordering::Less => i += 1,
                        std::cmp::Ordering::Greater => j += 1,
                    }
                }
                (wrong, hit, want)
            }
            Capacity::Nearest => {
                let mine = sorted(result, p);
                let wrong = mine.first().map(|f| f.depth) != Some(tp[0].depth);
                (wrong, mine.len().min(1), 1)
            }
            Capacity::Image => {
                let want = crate::common::composite_frags(tp, params.alpha, params.background);
                let got = result.image.as_ref().map(|i| i[p]).unwrap_or([f32::NAN; 4]);
                // NaN counts as wrong.
                let wrong = (0..3).any(|c| {
                    let d = (got[c] - want[c]).abs();
                    d.is_nan() || d > IMAGE_TOLERANCE
                });
                (wrong, tp.len(), tp.len())
            }
        };
        m.captured += captured as u64;
        m.expected += expected as u64;
        if wrong {
            m.error_pixels += 1;
            m.error_mask[p] = true;
            if m.first_error.is_none() {
                m.first_error = Some(((p as u32) % t.width, (p as u32) / t.width));
            }
        }
    }
    if m.covered_pixels > 0 {
        m.epr = m.error_pixels as f64 / m.covered_pixels as f64;
        m.coplanarity /= m.covered_pixels as f64;
    }
    m.robustness = if m.expected > 0 {
        m.captured as f64 / m.expected as f64
    } else {
        1.0
    };
    if let Some(im) = image.as_mut() {
        if m.covered_pixels > 0 {
            im.image_epr = im.error_pixels as f64 / m.covered_pixels as f64;
            im.mse = squared / (3 * m.covered_pixels) as f64;
        }
        im.psnr = -10.0 * im.mse.log10();
    }
    m.image = image;
    m
}

fn sorted(result: &AlgoResult, p: usize) -> Vec<CapturedFrag> {
    let mut v = result
        .capture
        .as_ref()
        .map(|c| c.pixel(p).to_vec())
        .unwrap_or_default();
    v.sort_by(depth_order);
    v
}

fn same_frags(a: &[CapturedFrag], b: &[CapturedFrag]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.depth == y.depth && x.prim == y.prim)
}
