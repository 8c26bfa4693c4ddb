//! `kb-spinlock`: Bavoil's read-modify-write k-buffer (see [`super::rmw`]) inside a per-pixel
//! spinlock, as it is written where pixel interlock is missing (the "pixel synchronization"
//! k-buffers the occupancy paper, section 1, cites, emulated in software; the known hazards of docs/hazards.md,
//! "spinlock k-buffer").
//!
//! Acquire: compare-exchange of the pixel's lock word 0 -> 1 (acquire), retried; each attempt
//! is one step, where other invocations may run. Release: an atomic store of 0 (release).
//! After `params.spin_cap` failed attempts (at least 1) the fragment gives up: it is **dropped
//! and counted** (per pixel, reported in [`AlgoResult::dropped`] and a check), never silently.
//!
//! Why it is declared hazard-prone (docs/hazards.md): a spinlock gives no forward progress
//! guarantee. A lock holder that the scheduler does not run (a PCT priority drop, an
//! OS-descheduled thread) makes every other fragment of its pixel burn its cap and give up,
//! so with any finite cap some schedules drop fragments (EPR > 0; with the default cap of
//! 1024, `pct:3` does on every built-in scene at 48 x 48); without a cap they hang (the
//! watchdog's business).
//! What does hold under every interleaving, and is checked: mutual exclusion (entries
//! counted with plain read-modify-writes inside the lock add up, with the give-ups, to the
//! fragments shaded), every lock released, slots well formed; and errors only at pixels
//! that dropped fragments (tested against the truth). The detector reports no hazard on the
//! plain accesses inside the lock: the atomic-store release and the compare-exchange acquire
//! order them, as the emulator's acquire-release atomics do (docs/hazards.md). On a GPU,
//! whose atomics are relaxed, the slots would also need `coherent` and `memoryBarrier()`.
//!
//! In the parallel executor the lanes of a warp advance in lockstep (one step each in turn),
//! so a holder in the spinner's own warp always progresses, and a holder in another warp
//! runs on another thread, which the OS may deschedule: even the default cap runs out there
//! (seen with 4 threads on 2 cores).
//!
//! On GPUs without independent thread scheduling (the scheduled executor's `simt` mode) it is
//! the other way round: a holder cannot run its release while warp-mates spin on its lock,
//! so with the cap every such warp-mate gives up, and without one (`spin_cap` u32::MAX) the
//! warp deadlocks (a reported `SimtDeadlock` fault; `kernels/tests/simt.rs`).

use fragrace_emu::{Buf, ExecConfig, Fragment, FragmentKernel, KernelInfo};

use super::checks::Shape;
use super::run::KbRun;
use super::slots::{rmw_insert, Slots, SplitSlots};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(KbSpinlock)]
}

pub struct SpinStore {
    pub kb: SplitSlots,
    pub k: u32,
    /// Per pixel: 0 free, 1 held.
    pub lock: Buf<u32>,
    /// Lock attempts before giving up (at least 1).
    pub cap: u32,
    /// Per pixel: fragments that gave up.
    pub gave_up: Buf<u32>,
    /// Per pixel: critical sections entered (plain read-modify-write inside the lock).
    pub entries: Buf<u32>,
}

impl FragmentKernel for SpinStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-spinlock-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let mut attempts = 0;
        loop {
            if f.atomic_compare_exchange(self.lock, p, 0, 1).await.is_ok() {
                break;
            }
            attempts += 1;
            if attempts >= self.cap {
                f.atomic_add(self.gave_up, p, 1).await;
                return;
            }
        }
        let e = f.load(self.entries, p).await;
        f.store(self.entries, p, e + 1).await;
        rmw_insert(
            f,
            self.kb,
            p * self.k,
            self.k as usize,
            f.depth(),
            f.primitive_id(),
        )
        .await;
        f.atomic_store(self.lock, p, 0).await;
    }
}

/// What a spinlock run leaves besides the result: per-pixel give-ups (for tests that
/// relate error pixels to drops).
pub(super) struct SpinRun {
    pub result: AlgoResult,
    /// Give-ups per pixel, row-major.
    #[cfg_attr(not(test), allow(dead_code))] // read by the tests
    pub gave_up: Vec<u32>,
}

/// `kb-spinlock`: see the module documentation.
pub struct KbSpinlock;

impl KbSpinlock {
    pub(super) fn run_detailed(
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<SpinRun, AlgoError> {
        let mut run = KbRun::new(frame, params, exec)?;
        let kb = SplitSlots::new(&mut run.device, run.n, run.k)?;
        let lock = run.device.buffer::<u32>("kb-lock", run.n as u64)?;
        let gave_up = run.device.buffer::<u32>("kb-gave-up", run.n as u64)?;
        let entries = run.device.buffer::<u32>("kb-entries", run.n as u64)?;
        let cap = params.spin_cap.max(1);
        let report = run.capture(&SpinStore {
            kb,
            k: run.k,
            lock,
            cap,
            gave_up,
            entries,
        })?;
        let slots = Slots::Split(kb);
        let shape = Shape::of(&slots.read(&run.device, run.k)?, true, None);
        let given_up = run.device.memory.read(gave_up)?;
        let dropped: u64 = given_up.iter().map(|&g| g as u64).sum();
        let entered = run.total(entries)?;
        let held = run
            .device
            .memory
            .read(lock)?
            .iter()
            .filter(|&&l| l != 0)
            .count();
        let shaded = report.stats.shaded;
        let checks = vec![
            shape.check(frame.width, false),
            Check::new(
                "every fragment entered the lock once or gave up (mutual exclusion, nothing silent)",
                entered + dropped == shaded,
                format!("entries {entered} + give-ups {dropped}, fragments shaded {shaded}"),
            ),
            Check::new("every lock released", held == 0, format!("{held} locks still held")),
            Check::new(
                "fragments dropped at the spin cap (informational: the hazard of a spinlock)",
                true,
                format!(
                    "{dropped} fragments gave up after {cap} attempts, at {} pixels",
                    given_up.iter().filter(|&&g| g > 0).count()
                ),
            ),
        ];
        let result = run.finish(slots, report, checks, dropped, 0)?;
        Ok(SpinRun {
            result,
            gave_up: given_up,
        })
    }
}

impl Algorithm for KbSpinlock {
    /// k, and the cap of its spin lock.
    fn reads(&self, p: crate::Param) -> bool {
        matches!(p, crate::Param::K | crate::Param::SpinCap)
    }

    /// Its capture passes run through `KbRun::capture`, which puts them behind occupancy
    /// culling when asked.
    fn takes_occupancy(&self) -> bool {
        true
    }
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "kb-spinlock",
            family: "k-buffer",
            summary: "read-modify-write k-buffer inside a per-pixel spinlock (compare-exchange acquire, atomic-store \
                      release); fragments that reach the spin cap are dropped and counted",
            source: "pixel synchronization k-buffers (occupancy paper, section 1) without hardware interlock; \
                     spinlock k-buffer (docs/hazards.md); Bavoil et al. 2007 (I3D)",
            passes: "1 geometry + 1 full-screen (resolve)",
            memory: "8 k + 12 bytes: k depths + k primitive ids (Table 1, KB: 2K + 2 words) + the lock + the entry \
                     and give-up counts of the invariants; + 16-byte resolve target",
            hazard: HazardClass::HazardProne,
            capacity: Capacity::KNearest,
        }
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        Ok(KbSpinlock::run_detailed(frame, params, exec)?.result)
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{ExecConfig, Policy};

    use super::*;
    use crate::basic::Truth;
    use crate::oracle;
    use crate::testing::*;

    /// Runs under `exec` and asserts the invariants and that every error pixel dropped a
    /// fragment; returns (dropped, error pixels).
    fn run_spin(params: &Params, exec: &ExecConfig, what: &str) -> (u64, u64) {
        let mesh = quads(16);
        let frame = frame(&mesh, 12);
        let s = KbSpinlock::run_detailed(&frame, params, exec).expect("runs");
        assert_checks(&s.result, what);
        assert_image_matches_capture(&s.result, params, what);
        let truth = Truth::capture(&frame, 1).unwrap();
        let m = oracle::compare(&KbSpinlock.info(), &s.result, &truth, params);
        for (p, &wrong) in m.error_mask.iter().enumerate() {
            assert!(
                !wrong || s.gave_up[p] > 0,
                "{what}: pixel {p} is wrong without a drop"
            );
        }
        assert_eq!(
            s.result.dropped,
            s.gave_up.iter().map(|&g| g as u64).sum::<u64>()
        );
        (s.result.dropped, m.error_pixels)
    }

    #[test]
    fn correct_except_counted_drops_under_every_executor() {
        let params = Params::default();
        for (what, exec) in executors(2) {
            let (dropped, wrong) = run_spin(&params, &exec, &what);
            if what == "ordered" || what.contains("fifo") {
                assert_eq!(
                    (dropped, wrong),
                    (0, 0),
                    "{what}: one fragment at a time never waits"
                );
            }
        }
    }

    #[test]
    fn a_small_cap_drops_fragments_under_scheduled_policies() {
        let params = Params {
            spin_cap: 1,
            ..Params::default()
        };
        // (Fifo, Reverse and far-first run one invocation until it retires unless a newly
        // admitted one preempts it, so they rarely contend for a lock.)
        for policy in [
            Policy::Random,
            Policy::Pct { depth: 3 },
            Policy::Warp { lanes: 32 },
        ] {
            for seed in 0..2 {
                let what = format!("cap 1, {policy} seed {seed}");
                let (dropped, wrong) = run_spin(&params, &scheduled(policy.clone(), seed), &what);
                assert!(dropped > 0, "{what}: contention makes fragments give up");
                assert!(wrong > 0, "{what}: and the k-buffer misses them (EPR > 0)");
            }
        }
        // Under parallel executors the same cap is correct wherever nothing dropped.
        run_spin(&params, &ExecConfig::parallel(2), "cap 1, parallel(2)");
    }

    #[test]
    fn the_detector_orders_the_plain_accesses_under_the_lock() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        let (r, m) = run(
            &KbSpinlock,
            &frame,
            &Params::default(),
            &scheduled(Policy::Random, 0),
        );
        // The atomic-store release and the compare-exchange acquire order each section
        // after the previous one (the detector's happens-before through atomics).
        assert_eq!(
            r.report.hazards.races, 0,
            "no race on the protected slots: {:?}",
            r.report.hazard_list.first()
        );
        assert_eq!(
            r.report.hazards.lost_updates, 0,
            "the lock excludes: no lost update"
        );
        assert_eq!(r.report.hazards.torn, 0, "nor torn records");
        assert_eq!(
            m.error_pixels, 0,
            "random schedules give the holder its turns"
        );
    }
}
