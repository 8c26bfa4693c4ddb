//! `bdp` and `bdp2`: bucket depth peeling over 16 uniform sub-intervals ("Efficient Depth
//! Peeling via Bucket Sort", section 3.2).
//!
//! "In the first geometry pass, we bind consecutive buckets into pairs and divide the depth
//! range into 16 subintervals: `[d_k, d_k+1)`, `d_k = zNear + k/16 (zFar - zNear)` ... the
//! corresponding bucket index k can be simply computed as `k = floor(16 (d_f - zNear) /
//! (zFar - zNear))` (2). Then the k-th pair of buckets will be updated by `(1 - d_f, d_f)`
//! and the rest pairs by `(0, 0)`." After the pass the pair holds `dmin_k^1` and `dmax_k^1`
//! (eq. 3), in depth order across pairs (eq. 4); an empty bucket stays 0, a pair of equal
//! depths is one fragment.
//!
//! `bdp2`: "In the second geometry pass, we allocate a new bucket array ... Those fragments
//! with depth values `d_f in [d_k, d_k+1)` satisfying condition `d_f >= dmax_k^1` or `d_f <=
//! dmin_k^1` have been captured in the previous pass, thus can be simply discarded." The
//! new pair holds `dmin_k^2`, `dmax_k^2`, and the read-out order is eq. 5: `dmin_k^1 <=
//! dmin_k^2 <= dmax_k^2 <= dmax_k^1` per sub-interval.
//!
//! The sub-interval is [`crate::occupancy::bits::bucket`] with 16 parts: eq. 2, clamped to
//! `[0, 15]` for a depth a bounding volume's range misses by a rounding step.

use fragrace_emu::{Buf, ExecConfig, Format, Fragment, FragmentKernel, Image, KernelInfo};

use super::{
    bucket_state, channel_of, channels, check_layers, depth_range, frag, from_min_key, max_key,
    min_key, Sorted, BUCKETS, TARGETS,
};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Frame, HazardClass, Params,
};
use crate::common::{framebuffer, geometry_pass, pixels};
use crate::occupancy::bits::bucket;

/// Uniform sub-intervals of the depth range: one min/max pair of buckets each.
pub const SUB_INTERVALS: u32 = (BUCKETS / 2) as u32;

/// Writes the pair of sub-interval `k`: `(1 - d_f, d_f)` into buckets `2k` and `2k + 1`,
/// `(0, 0)` into the others (one output per target, as MRTs are written).
#[inline(always)]
fn write_pair(f: &impl Fragment, k: usize, d: f32) {
    for t in 0..TARGETS {
        let mut v = [0.0f32; 4];
        if (2 * k) / 4 == t {
            v[(2 * k) % 4] = min_key(d);
            v[(2 * k) % 4 + 1] = max_key(d);
        }
        f.output(t, v);
    }
}

/// The first geometry pass: every fragment to the pair of its sub-interval.
struct BucketSort {
    near: Buf<f32>,
    far: Buf<f32>,
    /// Fragments routed to a bucket, per pixel.
    routed: Buf<u32>,
}

impl FragmentKernel for BucketSort {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bdp-bucket-sort")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z_near = f.load(self.near, p).await;
        let z_far = f.load(self.far, p).await;
        let d = f.depth();
        let k = bucket(d, z_near, z_far, SUB_INTERVALS) as usize;
        f.atomic_add(self.routed, p, 1).await;
        write_pair(&f, k, d);
    }
}

/// The second geometry pass of `bdp2`: fragments the first array holds are discarded, the
/// others go to the pair of their sub-interval in a new array.
struct SecondMinMax<'i> {
    near: Buf<f32>,
    far: Buf<f32>,
    first: &'i [Image],
}

impl FragmentKernel for SecondMinMax<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bdp2-second-min-max").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let z_near = f.load(self.near, p).await;
        let z_far = f.load(self.far, p).await;
        let d = f.depth();
        let k = bucket(d, z_near, z_far, SUB_INTERVALS) as usize;
        let dmin1 = from_min_key(f32::from_bits(channel_of(self.first, &f, 2 * k)));
        let dmax1 = f32::from_bits(channel_of(self.first, &f, 2 * k + 1));
        if dmin1.is_none_or(|dmin1| d <= dmin1) || d >= dmax1 {
            f.discard();
            return;
        }
        write_pair(&f, k, d);
    }
}

/// Appends the fragments of one pair (`min`, `max` keys in bits) in depth order.
fn push_pair(list: &mut Vec<CapturedFrag>, min: u32, max: u32) {
    let Some(lo) = from_min_key(f32::from_bits(min)) else {
        return;
    };
    list.push(frag(lo));
    // An empty max bucket beside a full min one: the pair's fragments are all at depth 0
    // (the min bucket holds it); equal depths are one fragment.
    let hi = f32::from_bits(max);
    if max != 0 && hi != lo {
        list.push(frag(hi));
    }
}

/// How many geometry passes of bucket sorting (besides the range pass).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Passes {
    /// `bdp`.
    One,
    /// `bdp2`.
    Two,
}

fn run(
    passes: Passes,
    frame: &Frame<'_>,
    params: &Params,
    exec: &ExecConfig,
) -> Result<AlgoResult, AlgoError> {
    let (name, arrays) = match passes {
        Passes::One => ("bdp", 1),
        Passes::Two => ("bdp2", 2),
    };
    let max_layers = (arrays * BUCKETS) as u32;
    check_layers(
        name,
        params.k,
        max_layers,
        &format!(
            "{arrays} x {SUB_INTERVALS} min/max bucket pairs, no batching; adp takes more layers, \
             in batches of {BUCKETS}"
        ),
    )?;
    let mut device = crate::common::fresh(exec);
    let (range, mut report) = depth_range(&mut device, frame, params, exec)?;
    let routed = device.buffer::<u32>("bdp-routed", pixels(frame) as u64)?;
    let state = bucket_state();

    let mut fb = framebuffer(frame, fragrace_emu::SampleCount::X1, &[Format::RGBA32F; 8])?;
    let sort = BucketSort {
        near: range.near,
        far: range.far,
        routed,
    };
    report.merge(&geometry_pass(
        &device, &mut fb, frame, &state, &sort, exec,
    )?);
    let first: Vec<Image> = (0..TARGETS).map(|t| fb.image(t)).collect();
    let second: Option<Vec<Image>> = match passes {
        Passes::One => None,
        Passes::Two => {
            let mut fb2 = framebuffer(frame, fragrace_emu::SampleCount::X1, &[Format::RGBA32F; 8])?;
            let again = SecondMinMax {
                near: range.near,
                far: range.far,
                first: &first,
            };
            report.merge(&geometry_pass(
                &device, &mut fb2, frame, &state, &again, exec,
            )?);
            Some((0..TARGETS).map(|t| fb2.image(t)).collect())
        }
    };

    let mut sorted = Sorted::new(frame);
    sorted.routed = device.memory.read(routed)?;
    for (p, list) in sorted.lists.iter_mut().enumerate() {
        let one = channels(&first, p);
        let two = second.as_ref().map(|s| channels(s, p));
        for k in 0..SUB_INTERVALS as usize {
            let (min1, max1) = (one[2 * k], one[2 * k + 1]);
            match &two {
                None => push_pair(list, min1, max1),
                Some(two) => {
                    // Eq. 5: dmin1 <= dmin2 <= dmax2 <= dmax1.
                    let Some(lo) = from_min_key(f32::from_bits(min1)) else {
                        continue;
                    };
                    list.push(frag(lo));
                    push_pair(list, two[2 * k], two[2 * k + 1]);
                    let hi = f32::from_bits(max1);
                    if max1 != 0 && hi != lo {
                        list.push(frag(hi));
                    }
                }
            }
        }
    }
    let target_bytes = (arrays * BUCKETS * 4) as u64 * pixels(frame) as u64;
    let storage = device.memory.bytes() + target_bytes;
    Ok(sorted.finish(params.k, report, Vec::new(), storage))
}

/// `bdp`: see the module documentation.
pub struct Bdp;

impl Algorithm for Bdp {
    fn takes_range(&self) -> bool {
        true
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "bdp",
            family: "bucket depth peeling",
            summary: "bucket depth peeling: one geometry pass sorts each pixel's fragments into 16 uniform \
                      sub-intervals of its depth range, a min/max pair of buckets each (MAX blending into 8 \
                      RGBA32F targets); up to 32 layers, fragments colliding in a bucket are lost",
            source: "Liu, Huang, Liu, Wu, \"Efficient Depth Peeling via Bucket Sort\" (HPG 2009), sections 3.1 \
                     and 3.2",
            passes: "1 geometry (depth range: the scene with --range exact, 12 triangles with bbox) + 1 geometry",
            memory: "140 bytes: 128 of targets (8 RGBA32F, 32 buckets) + 8 of range (near, far) + 4 of the \
                     routed-fragment counter (35 words)",
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
        run(Passes::One, frame, params, exec)
    }
}

/// `bdp2`: see the module documentation.
pub struct Bdp2;

impl Algorithm for Bdp2 {
    fn takes_range(&self) -> bool {
        true
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "bdp2",
            family: "bucket depth peeling",
            summary: "two-pass bucket depth peeling: a second geometry pass into a new bucket array discards \
                      what the first captured and keeps each sub-interval's second min/max; up to 64 layers",
            source: "Liu, Huang, Liu, Wu, \"Efficient Depth Peeling via Bucket Sort\" (HPG 2009), section 3.2 \
                     (multi-pass approach, eq. 5)",
            passes: "1 geometry (depth range) + 2 geometry",
            memory: "268 bytes: 256 of targets (two arrays of 8 RGBA32F; the first read as 8 textures by the \
                     second pass) + 8 of range + 4 of the counter (67 words)",
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
        run(Passes::Two, frame, params, exec)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(Bdp), Box::new(Bdp2)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_checks, frame, run as run_checked};

    /// `n` quads stacked at distinct depths over the same pixels, spread over `spread` of
    /// the NDC depth range from its near end.
    fn stack(n: usize, spread: f32) -> fragrace_emu::Mesh {
        let mut mesh = fragrace_emu::Mesh::default();
        for i in 0..n {
            let z = -0.9 + spread * i as f32 / n.max(2) as f32;
            crate::testing::tilted_quad(&mut mesh, [-0.9, 0.9, -0.9, 0.9], z, 0.0);
        }
        mesh
    }

    #[test]
    fn uniform_layers_are_exact_in_one_pass() {
        // 32 evenly spaced layers: two per sub-interval, each pair holds both.
        let mesh = stack(32, 1.8);
        let f = frame(&mesh, 8);
        let params = Params {
            k: 32,
            ..Params::default()
        };
        let (r, m) = run_checked(&Bdp, &f, &params, &ExecConfig::ordered());
        assert_checks(&r, "bdp");
        assert_eq!(m.error_pixels, 0, "{m:?}");
        assert_eq!(r.dropped, 0);
        // The range pass and the bucket pass.
        assert_eq!(r.report.stats.geometry_passes, 2);
    }

    #[test]
    fn clustered_layers_collide_and_the_second_pass_recovers_some() {
        // Layers packed into the first sub-intervals plus one far layer that stretches the
        // range: BDP keeps 2 per sub-interval, BDP2 4.
        let mut mesh = stack(8, 0.05);
        crate::testing::tilted_quad(&mut mesh, [-0.9, 0.9, -0.9, 0.9], 0.9, 0.0);
        let f = frame(&mesh, 8);
        let params = Params {
            k: 9,
            ..Params::default()
        };
        let (r1, m1) = run_checked(&Bdp, &f, &params, &ExecConfig::ordered());
        let (r2, m2) = run_checked(&Bdp2, &f, &params, &ExecConfig::ordered());
        assert_checks(&r1, "bdp");
        assert_checks(&r2, "bdp2");
        let per_pixel = |r: &AlgoResult| r.collisions.as_ref().unwrap().iter().copied().max();
        assert!(m1.error_pixels > 0 && r1.dropped > 0, "{m1:?}");
        assert!(r2.dropped < r1.dropped, "{} vs {}", r2.dropped, r1.dropped);
        assert!(m2.captured > m1.captured, "{m2:?} vs {m1:?}");
        // Every covered pixel: 9 fragments, collisions = 9 - kept.
        assert_eq!(
            per_pixel(&r1),
            Some(9 - (m1.captured / m1.covered_pixels) as u32)
        );
        assert_eq!(r2.report.stats.geometry_passes, 3);
    }

    #[test]
    fn more_layers_than_the_arrays_hold_are_refused() {
        let mesh = stack(2, 1.0);
        let f = frame(&mesh, 8);
        for (algo, k) in [(&Bdp as &dyn Algorithm, 33), (&Bdp2, 65)] {
            let params = Params {
                k,
                ..Params::default()
            };
            let msg = match algo.run(&f, &params, &ExecConfig::ordered()) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("{} took k = {k}", algo.info().name),
            };
            assert!(msg.contains(&format!("k = {k}")), "{msg}");
            assert!(msg.contains(&format!("1..={}", k - 1)), "{msg}");
        }
    }

    #[test]
    fn an_empty_view_is_refused() {
        let mut mesh = fragrace_emu::Mesh::default();
        // Entirely behind the far plane: clipped away, no depth anywhere.
        crate::testing::tilted_quad(&mut mesh, [-0.9, 0.9, -0.9, 0.9], 3.0, 0.0);
        let f = frame(&mesh, 8);
        let msg = match Bdp.run(&f, &Params::default(), &ExecConfig::ordered()) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("an empty view ran"),
        };
        assert!(
            msg.contains("--range exact") && msg.contains("8 x 8"),
            "{msg}"
        );
    }
}
