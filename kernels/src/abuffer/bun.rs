//! `bun-ll`: uniform buckets combined with linked lists (depth-fighting paper, section 3.1.4
//! "Combining BUN with LL"; BUN is Liu et al.'s uniform bucket peeling, its ref \[14\]).
//!
//! "We uniformly split the depth range ... and assign each subdivision to one bucket. Then,
//! we concurrently store all fragment information in each bucket using linked lists. ... A
//! node buffer is used to store all linked-list fragment data from all buckets. We explore a
//! non-adaptive scheme where all buckets can handle the same number of rasterized fragments.
//! The location of the next available space in the node buffer is managed through five
//! global unsigned int address counters. Each pixel contains five head pointers ... one for
//! each bucket. ... After the complete storage of all fragments, a post-sorting mechanism is
//! carried out in each bucket" (3.1.4). Here:
//! - the depth range is per pixel, from a first geometry pass of atomic min/max on the f32
//!   depths (BUN approximates it with a bounding-box pass; the exact range cannot leave a
//!   fragment outside every bucket);
//! - `params.buckets` buckets (the paper's five by default) of equal depth width; the node
//!   buffer is cut into as many equal regions, each with its own counter; a fragment whose
//!   bucket's region is full is dropped and counted per bucket;
//! - region size: `pool_per_pixel x pixels / buckets` nodes, or, when the pool is sized
//!   exactly (`None`), the largest bucket's count from a count pass (every region that size,
//!   as the paper's uniform scheme: no overflow, and the unused memory of the emptier buckets
//!   the paper's discussion points out is visible in `storage_bytes`);
//! - the resolve sorts each bucket's list and concatenates the buckets front to back (the
//!   bucket of a depth is monotonic in the depth, so the concatenation is in depth order).

use fragrace_emu::{Buf, ExecConfig, Fragment, FragmentKernel, KernelInfo};

use super::checks::CaptureOrder;
use super::list_resolve::ListResolve;
use super::ll::{list_insert, pool_from_params, ListPool};
use super::walk::Walk;
use super::run::AbRun;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};
use crate::resolve::Composite;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(BunLl)]
}

/// Bucket of depth `d` in `[zmin, zmax]` cut into `buckets` equal intervals. Every step is a
/// monotonic float operation, so the bucket never decreases with the depth (fragments of one
/// depth share a bucket, and the concatenation of sorted buckets is sorted). The kernels and
/// the host checks call this same function.
pub(super) fn bucket_of(d: f32, zmin: f32, zmax: f32, buckets: u32) -> u32 {
    let range = zmax - zmin;
    if range.is_nan() || range <= 0.0 {
        return 0;
    }
    let t = ((d - zmin) / range * buckets as f32).floor();
    if t >= 0.0 {
        (t as u32).min(buckets - 1)
    } else {
        0
    }
}

/// Pass 1: the depth range of every pixel (atomic min and max on f32 depths).
struct RangeKernel {
    zmin: Buf<f32>,
    zmax: Buf<f32>,
}

impl FragmentKernel for RangeKernel {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bun-ll-range")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        f.atomic_min(self.zmin, p, f.depth()).await;
        f.atomic_max(self.zmax, p, f.depth()).await;
    }
}

/// The bucket of the invoking fragment, from its pixel's range.
async fn bucket(f: &impl Fragment, zmin: Buf<f32>, zmax: Buf<f32>, buckets: u32) -> u32 {
    let p = f.pixel_index();
    let lo = f.load(zmin, p).await;
    let hi = f.load(zmax, p).await;
    bucket_of(f.depth(), lo, hi, buckets)
}

/// Pass 2 (exact sizing only): fragments per bucket, on one global counter per bucket.
struct BucketCount {
    zmin: Buf<f32>,
    zmax: Buf<f32>,
    counts: Buf<u32>,
    buckets: u32,
}

impl FragmentKernel for BucketCount {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bun-ll-count")
    }
    async fn shade(&self, f: impl Fragment) {
        let b = bucket(&f, self.zmin, self.zmax, self.buckets).await;
        f.atomic_add(self.counts, b, 1).await;
    }
}

/// Pass 3: insert into the list of the fragment's bucket, with a node of that bucket's region.
struct BunInsert {
    zmin: Buf<f32>,
    zmax: Buf<f32>,
    pool: ListPool,
    buckets: u32,
    region: u32,
}

impl FragmentKernel for BunInsert {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("bun-ll-insert")
    }
    async fn shade(&self, f: impl Fragment) {
        let b = bucket(&f, self.zmin, self.zmax, self.buckets).await;
        let head = f.pixel_index() * self.buckets + b;
        list_insert!(f, self.pool, head, b, b * self.region, self.region, false);
    }
}

/// `bun-ll`: uniform depth buckets, each a set of per-pixel linked lists.
pub struct BunLl;

impl Algorithm for BunLl {
    /// Neither k (it keeps every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "bun-ll",
            family: "a-buffer",
            summary: "uniform buckets + linked lists: per-pixel depth range (atomic min/max), `buckets` equal \
                      intervals each with its own node region, counter and per-pixel head; post-sort per bucket; \
                      buckets concatenated front to back",
            source: "depth-fighting paper, section 3.1.4 (BUN [14] combined with LL [24]), Table 1 (BUN-LL)",
            passes: "2 geometry (range, store; +1 bucket count pass when the pool is sized exactly) + 1 full-screen",
            memory: "8 + 4 B + 12 n bytes (depth range; B heads; depth, primitive, next per node, n = B equal regions)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::All,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut run = AbRun::new(frame, params, exec)?;
        // The resolve writes nothing back; the host sorts the lists it reads (`Walk`).
        run.order = CaptureOrder::Host;
        let n = run.n;
        let buckets = params.buckets.max(1);
        let zmin = run.device.buffer::<f32>("bun-ll-zmin", n as u64)?;
        let zmax = run.device.buffer::<f32>("bun-ll-zmax", n as u64)?;
        run.device.memory.fill(zmin, f32::INFINITY)?;
        run.device.memory.fill(zmax, f32::NEG_INFINITY)?;
        let mut report = run.capture(&RangeKernel { zmin, zmax })?;

        let mut counted = None;
        let region = match params.pool_per_pixel {
            Some(per_pixel) => pool_from_params(per_pixel, n) / buckets as u64,
            None => {
                let counts = run
                    .device
                    .buffer::<u32>("bun-ll-bucket-counts", buckets as u64)?;
                report.merge(&run.capture(&BucketCount {
                    zmin,
                    zmax,
                    counts,
                    buckets,
                })?);
                let c = run.device.memory.read(counts)?;
                let max = c.iter().copied().max().unwrap_or(0) as u64;
                counted = Some(c);
                max
            }
        };
        // ListPool::new refuses a pool larger than a buffer (before the u32 casts are used).
        let pool_nodes = region * buckets as u64;
        let region = region as u32;
        let pool = ListPool::new(
            &mut run.device,
            "bun-ll",
            n as u64 * buckets as u64,
            pool_nodes,
            buckets as u64,
        )?;
        let faults = run.device.buffer::<u32>("bun-ll-resolve-faults", 2)?;

        let store = BunInsert {
            zmin,
            zmax,
            pool,
            buckets,
            region,
        };
        let resolve = ListResolve {
            pool,
            lists: buckets,
            pool_nodes: pool_nodes as u32,
            faults,
            composite: Composite::of(params),
            // The buckets' regions are not cut into screen blocks.
            blocks: None,
        };
        let generated = run.store_and_resolve(&mut report, &store, &resolve)?;

        let memory = &run.device.memory;
        let counters = memory.read(pool.counters)?;
        let dropped_counters = memory.read(pool.dropped)?;
        let regions: Vec<(u32, u32)> = (0..buckets)
            .map(|b| (b * region, b * region + counters[b as usize].min(region)))
            .collect();
        let walk = Walk::new(
            &memory.read(pool.heads)?,
            &memory.read(pool.nodes)?,
            buckets,
            &regions,
        );
        let capture = walk.capture(frame, buckets);
        let zmin_v = memory.read(zmin)?;
        let zmax_v = memory.read(zmax)?;

        let per_bucket_stored: Vec<u64> = (0..buckets as usize)
            .map(|b| {
                walk.lists
                    .iter()
                    .skip(b)
                    .step_by(buckets as usize)
                    .map(|l| l.len() as u64)
                    .sum()
            })
            .collect();
        let overflow: Vec<u64> = counters
            .iter()
            .map(|&c| c.saturating_sub(region) as u64)
            .collect();
        let dropped: u64 = overflow.iter().sum();
        let all_linked =
            (0..buckets as usize).all(|b| per_bucket_stored[b] == counters[b].min(region) as u64);
        let mut misplaced = 0usize;
        let mut first_misplaced = None;
        for (i, list) in walk.lists.iter().enumerate() {
            let (p, b) = (i / buckets as usize, (i % buckets as usize) as u32);
            for fr in list {
                let inside = zmin_v[p] <= fr.depth && fr.depth <= zmax_v[p];
                if !inside || bucket_of(fr.depth, zmin_v[p], zmax_v[p], buckets) != b {
                    misplaced += 1;
                    first_misplaced.get_or_insert((p, b, fr.depth));
                }
            }
        }
        let checks = vec![
            Check::new(
                "every generated fragment stored exactly once unless its bucket overflowed",
                walk.stored + dropped == generated && all_linked && walk.revisits == 0,
                format!(
                    "stored {} per bucket {per_bucket_stored:?}, dropped {dropped}, generated {generated}; region {region} nodes",
                    walk.stored
                ),
            ),
            Check::new(
                "overflow counted exactly (per bucket)",
                dropped_counters.iter().zip(&overflow).all(|(&d, &o)| d as u64 == o),
                format!("dropped counters {dropped_counters:?}, max(counter - region, 0) {overflow:?}"),
            ),
            walk.integrity_check(&memory.read(faults)?),
            Check::new(
                "every fragment in its pixel's depth range and in the bucket of its depth",
                misplaced == 0,
                format!(
                    "{misplaced} misplaced{}",
                    first_misplaced.map(|(p, b, d)| format!("; first: pixel {p}, bucket {b}, depth {d}")).unwrap_or_default()
                ),
            ),
        ];
        let later = counted.map(|c| {
            Check::new(
                "count pass equals store pass (per bucket)",
                c == counters,
                format!("counted {c:?}, stored {counters:?}"),
            )
        });
        Ok(run.finish(capture, report, dropped, checks, later))
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::Policy;

    use super::*;
    use crate::basic::Truth;
    use crate::oracle;
    use crate::testing::*;

    #[test]
    fn bun_ll_is_exact_and_hazard_free_under_every_executor() {
        assert_exact_and_hazard_free_everywhere(&BunLl);
        let mesh = layers();
        let f = frame_sized(&mesh, 24, 20);
        for buckets in [1, 2, 7] {
            let params = Params {
                buckets,
                ..Params::default()
            };
            for exec in [
                ExecConfig::ordered(),
                ExecConfig::parallel(3),
                ExecConfig::scheduled(Policy::Random, buckets as u64),
            ] {
                assert_exact(&BunLl, &f, &params, &exec);
            }
        }
        let roomy = Params {
            pool_per_pixel: Some(30.0),
            ..Params::default()
        };
        assert_exact(
            &BunLl,
            &f,
            &roomy,
            &ExecConfig::scheduled(Policy::Pct { depth: 3 }, 4),
        );
        let deep = stack(21);
        let f = frame_sized(&deep, 4, 3);
        assert_exact(
            &BunLl,
            &f,
            &Params {
                buckets: 2,
                ..Params::default()
            },
            &ExecConfig::parallel(2),
        );
    }

    #[test]
    fn bun_ll_bucket_overflow_is_counted_per_bucket() {
        // Every pixel: 5 layers spread over its range, so each of 5 buckets gets about one
        // fragment per pixel; a pool of 2 nodes per pixel (2 * 20 / 5 = 8 nodes a bucket)
        // keeps 8 fragments in each bucket and drops the rest.
        let mesh = stack(5);
        let f = frame_sized(&mesh, 5, 4);
        let params = Params {
            pool_per_pixel: Some(2.0),
            ..Params::default()
        };
        let truth = Truth::capture(&f, 1).unwrap();
        for exec in executor_configs() {
            let r = BunLl.run(&f, &params, &exec).unwrap();
            for c in &r.checks {
                assert!(c.passed, "{:?}: `{}`: {}", exec.mode, c.name, c.detail);
            }
            let m = oracle::compare(&BunLl.info(), &r, &truth, &params);
            assert_eq!(m.generated, 100);
            assert_eq!(m.captured + r.dropped, 100, "{:?}", exec.mode);
            assert!(
                m.captured <= 40 && r.dropped >= 60,
                "{:?}: captured {}",
                exec.mode,
                m.captured
            );
        }
    }

    #[test]
    fn bucket_of_is_monotonic_and_clamped() {
        assert_eq!(bucket_of(0.3, 0.3, 0.3, 5), 0);
        assert_eq!(bucket_of(0.9, 0.1, 0.9, 5), 4);
        assert_eq!(bucket_of(0.1, 0.1, 0.9, 5), 0);
        let (lo, hi) = (0.123_f32, 0.987_f32);
        let mut last = 0;
        for i in 0..=1000 {
            let d = lo + (hi - lo) * i as f32 / 1000.0;
            let b = bucket_of(d.min(hi), lo, hi, 7);
            assert!(b >= last && b < 7);
            last = b;
        }
        assert_eq!(last, 6);
    }
}
