//! The interlock k-buffers: Bavoil's read-modify-write insertion (see [`super::rmw`]) inside
//! the per-pixel critical section of fragment shader interlock / rasterizer-ordered views
//! (pixel synchronization \[Sal13\], cited by the occupancy paper, section 1, as "ensures
//! accurate k-buffer construction", and used by the z-thickness paper, section 4.2, for its
//! k-buffer store pass: "other fragments coming towards the same pixel must wait for the
//! processing of an occupying fragment to end").
//!
//! - `kb-interlock`: ordered interlock (`pixel_interlock_ordered`): critical sections of one
//!   pixel are entered in API order, which for one draw is primitive order.
//! - `kb-interlock-unordered`: mutual exclusion only; the entry order is whatever the
//!   executor produced (known hazard, docs/hazards.md: "mutual exclusion but nondeterministic order"). The kept
//!   set does not depend on the order (insertion is by `(depth, primitive)`), so both are
//!   exact; only order-dependent quantities would differ.
//!
//! Instrumentation, inside the critical section: the last primitive that entered each
//! pixel (to check the order: a later entrant with a primitive id not above it is a
//! violation, counted with an atomic) and the number of entries per pixel (plain
//! read-modify-write: exact only if the critical section excludes, so it also checks mutual
//! exclusion: the sum must equal the fragments shaded).

use fragrace_emu::{Buf, ExecConfig, Fragment, FragmentKernel, InterlockMode, KernelInfo};

use super::checks::Shape;
use super::run::{counter_total, KbRun};
use super::slots::{rmw_insert, Slots, SplitSlots};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![
        Box::new(KbInterlock::ORDERED),
        Box::new(KbInterlock::UNORDERED),
    ]
}

pub struct InterlockStore {
    pub kb: SplitSlots,
    pub k: u32,
    pub mode: InterlockMode,
    /// Per pixel: primitive id + 1 of the last fragment that entered (0: none yet).
    pub last: Buf<u32>,
    /// Per pixel: critical sections entered.
    pub entries: Buf<u32>,
    /// Entries whose primitive id was not above the previous entrant's.
    pub out_of_order: Buf<u32>,
}

impl FragmentKernel for InterlockStore {
    fn info(&self) -> KernelInfo {
        let name = if self.mode.ordered {
            "kb-interlock-store"
        } else {
            "kb-interlock-unordered-store"
        };
        KernelInfo::new(name).with_interlock(self.mode)
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let prim = f.primitive_id();
        f.interlock_begin().await;
        let last = f.load(self.last, p).await;
        if last != 0 && prim.wrapping_add(1) <= last {
            f.atomic_add(self.out_of_order, 0, 1).await;
        }
        f.store(self.last, p, prim.wrapping_add(1)).await;
        let e = f.load(self.entries, p).await;
        f.store(self.entries, p, e + 1).await;
        rmw_insert(f, self.kb, p * self.k, self.k as usize, f.depth(), prim).await;
        f.interlock_end().await;
    }
}

/// `kb-interlock` and `kb-interlock-unordered`: see the module documentation.
pub struct KbInterlock {
    mode: InterlockMode,
}

impl KbInterlock {
    pub const ORDERED: KbInterlock = KbInterlock {
        mode: InterlockMode::ORDERED,
    };
    pub const UNORDERED: KbInterlock = KbInterlock {
        mode: InterlockMode::UNORDERED,
    };
}

impl Algorithm for KbInterlock {
    /// Its capture passes run through `KbRun::capture`, which puts them behind occupancy
    /// culling when asked.
    fn takes_occupancy(&self) -> bool {
        true
    }
    fn info(&self) -> AlgoInfo {
        let (name, summary) = if self.mode.ordered {
            (
                "kb-interlock",
                "Bavoil's read-modify-write k-buffer inside ordered pixel interlock (critical sections in primitive \
                 order)",
            )
        } else {
            (
                "kb-interlock-unordered",
                "Bavoil's read-modify-write k-buffer inside unordered pixel interlock (mutual exclusion, any order)",
            )
        };
        AlgoInfo {
            name,
            family: "k-buffer",
            summary,
            source: "pixel synchronization [Sal13] (occupancy paper, section 1); z-thickness paper, section 4.2; \
                     Bavoil et al. 2007 (I3D)",
            passes: "1 geometry + 1 full-screen (resolve)",
            memory: "8 k + 8 bytes: k depths + k primitive ids (Table 1, KB: 2K + 2 words) + the last entrant and \
                     entry count of the invariants; + 16-byte resolve target",
            hazard: HazardClass::NeedsInterlock,
            capacity: Capacity::KNearest,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut run = KbRun::new(frame, params, exec)?;
        let kb = SplitSlots::new(&mut run.device, run.n, run.k)?;
        let last = run.device.buffer::<u32>("kb-last-entrant", run.n as u64)?;
        let entries = run.device.buffer::<u32>("kb-entries", run.n as u64)?;
        let out_of_order = run.device.buffer::<u32>("kb-out-of-order", 1)?;
        let store = InterlockStore {
            kb,
            k: run.k,
            mode: self.mode,
            last,
            entries,
            out_of_order,
        };
        let report = run.capture(&store)?;
        let slots = Slots::Split(kb);
        let shaded = report.stats.shaded;
        let (width, ordered) = (frame.width, self.mode.ordered);
        // The invariants read the slots and counters back after the frame
        // ([`AlgoResult::deferred`]).
        run.finish_deferred(slots, report, 0, 0, move |device, raw| {
            let shape = Shape::of(raw, true, None);
            let entered = counter_total(device, entries)?;
            let disorder = device.memory.read(out_of_order)?[0];
            Ok(vec![
                shape.check(width, false),
                Check::new(
                    "every fragment entered its pixel's critical section exactly once (mutual exclusion)",
                    entered == shaded,
                    format!(
                        "entries counted inside the critical sections {entered}, fragments shaded {shaded}"
                    ),
                ),
                if ordered {
                    Check::new(
                        "critical sections entered in primitive order per pixel",
                        disorder == 0,
                        format!("{disorder} entries after a later primitive"),
                    )
                } else {
                    Check::new(
                        "entries out of primitive order (informational: unordered interlock does not order)",
                        true,
                        format!("{disorder} entries after a later primitive"),
                    )
                },
            ])
        })
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::Policy;

    use super::*;
    use crate::testing::*;

    #[test]
    fn ordered_exact_under_every_executor() {
        assert_exact_everywhere(&KbInterlock::ORDERED, &Params::default(), 3);
    }

    #[test]
    fn unordered_exact_under_every_executor() {
        assert_exact_everywhere(&KbInterlock::UNORDERED, &Params::default(), 3);
    }

    #[test]
    fn no_hazards_inside_the_critical_section() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        for algo in [KbInterlock::ORDERED, KbInterlock::UNORDERED] {
            for seed in 0..3 {
                let (r, _) = run(
                    &algo,
                    &frame,
                    &Params::default(),
                    &scheduled(Policy::Random, seed),
                );
                assert_eq!(
                    r.report.hazards.total(),
                    0,
                    "{}: {:?}",
                    algo.info().name,
                    r.report.hazard_list.first()
                );
            }
        }
    }

    #[test]
    fn unordered_interlock_enters_out_of_order_under_random_schedules() {
        let mesh = quads(16);
        let frame = frame(&mesh, 8);
        let (r, _) = run(
            &KbInterlock::UNORDERED,
            &frame,
            &Params::default(),
            &scheduled(Policy::Random, 1),
        );
        let c = r
            .checks
            .iter()
            .find(|c| c.name.starts_with("entries out of primitive order"))
            .unwrap();
        assert!(
            !c.detail.starts_with("0 "),
            "random schedules reorder entries: {}",
            c.detail
        );
        // Reverse runs the latest fragment first: entirely out of order, still exact.
        let (r, m) = run(
            &KbInterlock::UNORDERED,
            &frame,
            &Params::default(),
            &scheduled(Policy::Reverse, 0),
        );
        assert_eq!(m.error_pixels, 0);
        let c = r
            .checks
            .iter()
            .find(|c| c.name.starts_with("entries out of primitive order"))
            .unwrap();
        assert!(!c.detail.starts_with("0 "), "{}", c.detail);
    }
}
