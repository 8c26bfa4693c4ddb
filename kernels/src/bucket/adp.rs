//! `adp`: adaptive bucket depth peeling ("Efficient Depth Peeling via Bucket Sort", section
//! 3.3 and Table 1).
//!
//! Table 1, line by line:
//!
//! 1-3. `ZNearZFar <- DrawBoundingBox()`: the range pass ([`super::depth_range`]).
//! 4-6. `Histogram <- DrawModel(ZNearZFar)` with `LOGIC_OR` ([`Histogram`]): "we allocate 8
//!    MRT buffers with pixel format GL_RGBA32UI_EXT as our depth histogram ... a bit array
//!    of size 4 x 8 x 32 = 1024 ... an incoming fragment within the k-th subinterval will
//!    set the k-th bit of the depth histogram to 1".
//! 7. `EqualizedHistogram <- HistogramEqualization(Histogram)` ([`Equalize`], full screen):
//!    "If the bit is zero ... [it] can be simply skipped over; otherwise ... we store the
//!    corresponding upper bound `d_k+1` consecutively into the equalized histogram".
//! 8-10. `BucketArray <- DrawModel(EqualizedHistogram)` with `MAX_BLENDING` ([`Route`]):
//!    "each incoming fragment ... will search the input equalized histogram ... If it
//!    belongs to the k-th subinterval, i.e., it satisfies conditions `d_f >= EH[k-1]` and
//!    `d_f < EH[k]`, it will be routed to the k-th bucket."
//!
//! **Batches.** "For scenes with more than 32 layers, we can handle the remaining layers by
//! scanning over the remaining part of the histogram in a new fullscreen pass to get another
//! batch of 32 nonzero bits. We then equalize it and pass the equalized histogram to the next
//! geometry pass to route the fragments between layer 32 and 64 ... and so on." Batch `t`
//! skips the first `32 t` set bits; a fragment at or before the last bound of batch `t - 1`
//! was routed then and is discarded, one beyond the batch's last bound waits for the next.
//! The host runs `ceil(min(L, k) / 32)` batches, `L` the most set bits of any pixel (read
//! back from the histogram, as the peelers read back their occlusion queries).
//!
//! **Bounds.** An upper bound here is the largest depth of its sub-interval
//! ([`crate::occupancy::bits::bucket_bound`]), and a fragment goes to the first bucket whose
//! bound it does not exceed: `EH[k-1] < d_f <= EH[k]`. The paper's `zNear + (k+1)/1024
//! (zFar - zNear)` can round to either side of a fragment that the histogram put in
//! sub-interval `k`; the largest depth of the sub-interval cannot, so every fragment finds
//! the bucket of its own bit. Fragments sharing a bit (closer than `(zFar - zNear) / 1024`)
//! share a bucket: the farthest stays, the others are the collisions (end of section 3.3).

use fragrace_emu::{
    Buf, ExecConfig, Format, Fragment, FragmentKernel, FragmentState, Image, KernelInfo,
    TargetState,
};

use super::{
    bucket_state, channel_of, channels, check_layers, depth_range, frag, histogram_state, max_key,
    write_bits, write_bucket, Sorted, BUCKETS, TARGETS,
};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Frame, HazardClass, Params,
};
use crate::common::{framebuffer, geometry_pass, pixels};
use crate::occupancy::bits::{bucket, bucket_bound, BITS_PER_WORD};

/// Sub-intervals of the depth histogram: `4 x 8 x 32` bits.
pub const HISTOGRAM_BITS: u32 = (BUCKETS as u32) * BITS_PER_WORD;

/// An equalised histogram's channel without a bound (past the pixel's last set bit).
const NO_BOUND: f32 = f32::NEG_INFINITY;

/// Geometry pass 1: each fragment sets the bit of its sub-interval (logic OR).
struct Histogram {
    near: Buf<f32>,
    far: Buf<f32>,
}

impl FragmentKernel for Histogram {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("adp-histogram")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z_near = f.load(self.near, p).await;
        let z_far = f.load(self.far, p).await;
        let k = bucket(f.depth(), z_near, z_far, HISTOGRAM_BITS);
        write_bits(&f, (k / BITS_PER_WORD) as usize, 1 << (k % BITS_PER_WORD));
    }
}

/// The equalisation pass (full screen): the upper bounds of the set bits `skip ..
/// skip + 32` of the pixel's histogram, in order, into 32 channels.
struct Equalize<'i> {
    near: Buf<f32>,
    far: Buf<f32>,
    histogram: &'i [Image],
    skip: u32,
}

impl Equalize<'_> {
    fn state() -> FragmentState {
        let mut s = FragmentState::new();
        s.targets = vec![TargetState::new(Format::RGBA32F); TARGETS];
        s
    }
}

impl FragmentKernel for Equalize<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("adp-equalize")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z_near = f.load(self.near, p).await;
        let z_far = f.load(self.far, p).await;
        let mut eh = [NO_BOUND; BUCKETS];
        let (mut seen, mut n) = (0u32, 0usize);
        'scan: for i in 0..BUCKETS {
            let channel = channel_of(self.histogram, &f, i);
            if channel == 0 {
                continue;
            }
            for j in 0..BITS_PER_WORD {
                if channel & (1 << j) == 0 {
                    continue;
                }
                if seen >= self.skip {
                    if n == BUCKETS {
                        break 'scan;
                    }
                    let k = i as u32 * BITS_PER_WORD + j;
                    eh[n] = bucket_bound(k, z_near, z_far, HISTOGRAM_BITS);
                    n += 1;
                }
                seen += 1;
            }
        }
        for t in 0..TARGETS {
            f.output(t, [eh[4 * t], eh[4 * t + 1], eh[4 * t + 2], eh[4 * t + 3]]);
        }
    }
}

/// Geometry pass 2 (one per batch): each fragment of the batch goes to the bucket of the
/// first bound it does not exceed (MAX blending).
struct Route<'i> {
    equalized: &'i [Image],
    /// The previous batch's equalised histogram (its last bound ends that batch).
    previous: Option<&'i [Image]>,
    routed: Buf<u32>,
}

impl FragmentKernel for Route<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("adp-route").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let d = f.depth();
        if let Some(previous) = self.previous {
            let last = f32::from_bits(channel_of(previous, &f, BUCKETS - 1));
            if d <= last {
                f.discard();
                return;
            }
        }
        for k in 0..BUCKETS {
            if d <= f32::from_bits(channel_of(self.equalized, &f, k)) {
                f.atomic_add(self.routed, f.pixel_index(), 1).await;
                write_bucket(&f, k, max_key(d));
                return;
            }
        }
        f.discard();
    }
}

/// `adp`: see the module documentation.
pub struct Adp;

impl Algorithm for Adp {
    fn takes_range(&self) -> bool {
        true
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "adp",
            family: "bucket depth peeling",
            summary: "adaptive bucket depth peeling: a 1024-bit depth histogram (logic OR into 8 RGBA32UI \
                      targets), equalised into the upper bounds of its non-empty sub-intervals, routes each \
                      fragment to a bucket of its own; batches of 32 layers",
            source: "Liu, Huang, Liu, Wu, \"Efficient Depth Peeling via Bucket Sort\" (HPG 2009), section 3.3 \
                     and Table 1",
            passes: "1 geometry (depth range) + 1 geometry (histogram) + per batch of 32 layers: 1 full-screen \
                     (equalisation) + 1 geometry (routing); ceil(min(L, k) / 32) batches, L the most \
                     non-empty sub-intervals of a pixel",
            memory: "396 bytes: 128 of histogram (8 RGBA32UI) + 128 of equalised histogram (8 RGBA32F) + 128 of \
                     buckets (8 RGBA32F) + 8 of range + 4 of the counter (99 words); + 128 for the previous \
                     batch's bounds when batching",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::KNearest,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        check_layers(
            "adp",
            params.k,
            HISTOGRAM_BITS,
            &format!("one per non-empty sub-interval of a {HISTOGRAM_BITS}-bit histogram"),
        )?;
        let mut device = crate::common::fresh(exec);
        let (range, mut report) = depth_range(&mut device, frame, params, exec)?;
        let n = pixels(frame);
        let routed = device.buffer::<u32>("adp-routed", n as u64)?;

        // Geometry pass 1: the histogram.
        let x1 = fragrace_emu::SampleCount::X1;
        let mut hist_fb = framebuffer(frame, x1, &[Format::RGBA32UI; TARGETS])?;
        let histogram = Histogram {
            near: range.near,
            far: range.far,
        };
        report.merge(&geometry_pass(
            &device,
            &mut hist_fb,
            frame,
            &histogram_state(),
            &histogram,
            exec,
        )?);
        let histogram: Vec<Image> = (0..TARGETS).map(|t| hist_fb.image(t)).collect();
        let most_bits = (0..n)
            .map(|p| {
                channels(&histogram, p)
                    .iter()
                    .map(|c| c.count_ones())
                    .sum::<u32>()
            })
            .max()
            .unwrap_or(0);
        let batches = most_bits.min(params.k).div_ceil(BUCKETS as u32);

        let mut sorted = Sorted::new(frame);
        let mut previous: Option<Vec<Image>> = None;
        for batch in 0..batches {
            // Equalisation of the batch's 32 set bits.
            let mut eh_fb = framebuffer(frame, x1, &[Format::RGBA32F; TARGETS])?;
            let equalize = Equalize {
                near: range.near,
                far: range.far,
                histogram: &histogram,
                skip: batch * BUCKETS as u32,
            };
            report.merge(&device.fullscreen(&mut eh_fb, &Equalize::state(), &equalize, exec)?);
            let equalized: Vec<Image> = (0..TARGETS).map(|t| eh_fb.image(t)).collect();
            // Geometry pass 2: routing into a new bucket array.
            let mut bucket_fb = framebuffer(frame, x1, &[Format::RGBA32F; TARGETS])?;
            let route = Route {
                equalized: &equalized,
                previous: previous.as_deref(),
                routed,
            };
            report.merge(&geometry_pass(
                &device,
                &mut bucket_fb,
                frame,
                &bucket_state(),
                &route,
                exec,
            )?);
            let buckets: Vec<Image> = (0..TARGETS).map(|t| bucket_fb.image(t)).collect();
            for (p, list) in sorted.lists.iter_mut().enumerate() {
                let (eh, b) = (channels(&equalized, p), channels(&buckets, p));
                for k in 0..BUCKETS {
                    // A bound stands for a set bit: some fragment was routed to its bucket.
                    if f32::from_bits(eh[k]) != NO_BOUND {
                        list.push(frag(f32::from_bits(b[k])));
                    }
                }
            }
            previous = Some(equalized);
        }
        sorted.routed = device.memory.read(routed)?;
        let batch_bytes = if batches > 1 { 4 * BUCKETS as u64 } else { 0 };
        let per_pixel = 3 * 4 * BUCKETS as u64 + batch_bytes;
        let storage = device.memory.bytes() + per_pixel * n as u64;
        let checks = vec![crate::algo::Check::new(
            "batches (informational)",
            true,
            format!(
                "{batches} batches of {BUCKETS}: at most {most_bits} non-empty sub-intervals in a pixel, k = {}",
                params.k
            ),
        )];
        Ok(sorted.finish(params.k, report, checks, storage))
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(Adp)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_checks, frame, run};

    /// `n` quads at distinct depths over the same pixels, clustered: the first `n - 1`
    /// within 15 % of the NDC depth range (farther apart than a histogram bit), the last
    /// one far behind.
    fn clustered(n: usize) -> fragrace_emu::Mesh {
        let mut mesh = fragrace_emu::Mesh::default();
        for i in 0..n - 1 {
            let z = -0.9 + 0.3 * i as f32 / n as f32;
            crate::testing::tilted_quad(&mut mesh, [-0.9, 0.9, -0.9, 0.9], z, 0.0);
        }
        crate::testing::tilted_quad(&mut mesh, [-0.9, 0.9, -0.9, 0.9], 0.9, 0.0);
        mesh
    }

    #[test]
    fn clustered_layers_get_a_bucket_each() {
        let mesh = clustered(20);
        let f = frame(&mesh, 8);
        let params = Params {
            k: 20,
            ..Params::default()
        };
        let (r, m) = run(&Adp, &f, &params, &ExecConfig::ordered());
        assert_checks(&r, "adp");
        assert_eq!(m.error_pixels, 0, "{m:?}");
        assert_eq!(r.dropped, 0);
        // Range, histogram, one batch of routing; one equalisation.
        assert_eq!(r.report.stats.geometry_passes, 3);
        assert_eq!(r.report.stats.fullscreen_passes, 1);
        // BDP loses most of them to the first sub-interval.
        let (b, mb) = run(&super::super::Bdp, &f, &params, &ExecConfig::ordered());
        assert!(mb.error_pixels > 0 && b.dropped > 0, "{mb:?}");
    }

    #[test]
    fn more_than_32_layers_in_batches() {
        let mesh = clustered(70);
        let f = frame(&mesh, 8);
        for (k, batches) in [(70, 3), (40, 2), (32, 1)] {
            let params = Params {
                k,
                ..Params::default()
            };
            let (r, m) = run(&Adp, &f, &params, &ExecConfig::parallel(2));
            assert_checks(&r, "adp");
            assert_eq!(m.error_pixels, 0, "k = {k}: {m:?}");
            assert_eq!(r.report.stats.geometry_passes, 2 + batches, "k = {k}");
            assert_eq!(r.report.stats.fullscreen_passes, batches, "k = {k}");
        }
    }

    #[test]
    fn fragments_closer_than_a_sub_interval_collide() {
        // Two layers 1e-6 apart (far below (zFar - zNear) / 1024) and one far away.
        let mut mesh = fragrace_emu::Mesh::default();
        for z in [-0.5, -0.5 + 2e-6, 0.8] {
            crate::testing::tilted_quad(&mut mesh, [-0.9, 0.9, -0.9, 0.9], z, 0.0);
        }
        let f = frame(&mesh, 8);
        let (r, m) = run(&Adp, &f, &Params::default(), &ExecConfig::ordered());
        assert_checks(&r, "adp");
        let collisions = r.collisions.as_ref().unwrap();
        assert_eq!(m.error_pixels, m.covered_pixels, "{m:?}");
        assert!(
            m.error_mask
                .iter()
                .zip(collisions)
                .all(|(&e, &c)| !e || c == 1),
            "each error pixel lost exactly one fragment"
        );
    }

    #[test]
    fn more_layers_than_the_histogram_holds_are_refused() {
        let mesh = clustered(3);
        let f = frame(&mesh, 8);
        let params = Params {
            k: 1025,
            ..Params::default()
        };
        let msg = Adp
            .run(&f, &params, &ExecConfig::ordered())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            msg.contains("k = 1025") && msg.contains("1..=1024"),
            "{msg}"
        );
    }
}
