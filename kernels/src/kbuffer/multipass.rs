//! `kb-multipass`: the multipass k-buffer (MultiKB) of Liu, Wei, Xu and Wu, "Multi-layer
//! depth peeling via fragment sort" (MSR-TR-2006-81; CAD/Graphics 2009), cited as \[19\] by the
//! depth-fighting paper (section 2: "Read-modify-write hazards (RMWH) during KB updates can
//! be fixed using a multi-pass variation of this algorithm"; Table 1 row MultiKB: 1...K
//! layers per iteration, 1 to K passes) and by the bucket-depth-peeling paper (section 2:
//! "tries to alleviate the RMW hazards by multi-pass approach, which guarantees to capture at
//! least one fragment per pixel each geometry pass").
//!
//! Each geometry pass runs Bavoil's racy read-modify-write k-buffer (see [`super::rmw`]) on
//! the fragments *behind* the last fragment certified so far, into the slots not yet
//! certified, and at the same time lets the fixed-function depth test (LESS, late, API
//! ordered whatever order the shaders ran in, so immune to the race) keep the nearest of
//! those fragments with its primitive id in a target: Liu et al.'s guarantee. A full-screen
//! merge pass then certifies, per pixel:
//!
//! - **clean pixels** (no two insertions of this pass overlapped in time): the whole
//!   k-buffer. Overlap is detected with a per-pixel in-flight counter (atomic add on entry,
//!   atomic sub on exit; an entrant that finds it non-zero marks the pixel dirty). Without
//!   overlap each insertion's acquire-add reads from the previous one's release-sub, so
//!   every read-modify-write saw all earlier ones: the slots are exactly the nearest
//!   fragments behind the bound, and a clean pixel is complete (either the slots are full,
//!   or every fragment behind the bound fit). This detector is this crate's way to know
//!   which slots are "certainly correct"; the seeds do not spell out Liu et al.'s.
//! - **dirty pixels**: only the depth-test nearest (exact by construction); the racy slots
//!   are cleared and the next pass resumes behind it.
//!
//! **Property (checked on every run).** The certified fragments of a pixel are, in order,
//! exactly its `min(k, n)` nearest in `(depth, primitive)` order, under every interleaving:
//! each pass's depth-test nearest is strictly behind the previous bound (checked in the
//! merge kernel), and clean slots agree with it (checked). Every active pixel gains at
//! least one certified fragment per pass, so the algorithm ends within k geometry passes
//! (checked). Races cost passes, never fragments.
//!
//! **Hazard class: hazard-prone, with a guarantee of progress and an exact result.** The
//! capture races by design: the detector reports its lost updates, races and torn records,
//! and how many passes a pixel needs depends on the interleaving (1 when nothing overlaps,
//! up to k). What races is never kept, so the result is the same under every executor,
//! policy and seed (EPR 0, asserted by this module's tests), as Liu et al. claim ("robust
//! against the unreliable parallel read-after-write behavior ... guaranteeing correct
//! transparency ordering"). It is declared hazard-prone because its memory accesses are:
//! the class describes what the detector must see, and the exactness is this algorithm's
//! own invariant.
//!
//! **Cost.** Under heavy contention nearly every pixel is dirty in every pass, so the
//! algorithm degrades to one certified fragment per pixel per pass, k passes: the
//! bucket-depth-peeling paper's observation (section 2) that "as the depth complexity of the
//! scenes increases, the RMW hazards will also increase and the performance of the algorithm
//! will degrade rapidly". Run one fragment at a time it needs a single pass.
//!
//! The depth test breaks depth ties by API order (the first of equal depths stays); for one
//! draw, a pixel's fragments arrive in primitive order, so that is the `(depth, primitive)`
//! order of the slots and of the truth. The clean-pixel agreement check would catch a
//! rasterizer that broke this.

use fragrace_emu::{
    Buf, CompareFunc, DepthState, EarlyTests, ExecConfig, Format, Fragment, FragmentKernel,
    FragmentState, Image, KernelInfo, SampleCount, TargetState,
};

use super::checks::Shape;
use super::run::KbRun;
use super::slots::{key_less, rmw_insert, Slots, SplitSlots, MAX_K};
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Check, Frame, HazardClass, Params,
};
use crate::common::{framebuffer, geometry_pass, EMPTY};

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(KbMultipass)]
}

/// The bound of a finished pixel: no fragment is behind `(+inf, EMPTY)`.
const DONE: (f32, u32) = (f32::INFINITY, EMPTY);

/// Counters of the merge passes (one word each in the `kb-mp-stats` buffer).
mod stat {
    /// Pixels still active after this merge (reset by the host before each merge).
    pub const ACTIVE: u32 = 0;
    /// Fragments certified.
    pub const CERTIFIED: u32 = 1;
    /// Depth-test nearest not strictly behind the bound (must stay 0).
    pub const NOT_BEHIND: u32 = 2;
    /// Clean pixels whose k-buffer disagrees with the depth test or is malformed (must stay 0).
    pub const CLEAN_DISAGREES: u32 = 3;
    /// Pixel-passes certified whole.
    pub const CLEAN: u32 = 4;
    /// Pixel-passes where insertions overlapped.
    pub const DIRTY: u32 = 5;
    /// Dirty pixel-passes where the race corrupted even the k-buffer's nearest slot.
    pub const DIRTY_WRONG_NEAREST: u32 = 6;
    pub const COUNT: u64 = 7;
}

/// Per-pixel state shared by the passes.
#[derive(Clone, Copy)]
struct State {
    /// Slots: `[0, found)` certified, `[found, k)` this pass's k-buffer.
    kb: SplitSlots,
    k: u32,
    /// The last certified fragment (`(-inf, 0)` before the first, [`DONE`] when finished).
    lo_depth: Buf<f32>,
    lo_prim: Buf<u32>,
    found: Buf<u32>,
    inflight: Buf<u32>,
    dirty: Buf<u32>,
    stats: Buf<u32>,
}

/// The capture pass: the racy k-buffer on the fragments behind the bound, and the nearest
/// of them through the depth test.
struct Capture {
    s: State,
}

impl FragmentKernel for Capture {
    fn info(&self) -> KernelInfo {
        // Discards: fragments at or before the bound must not reach the depth test.
        KernelInfo::new("kb-multipass-capture").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let s = &self.s;
        let p = f.pixel_index();
        let (z, prim) = (f.depth(), f.primitive_id());
        // The bound and the count are written only by the merge pass: no race here. The
        // bound's primitive is needed only on a depth tie, so fragments of finished pixels
        // and fragments in front of the bound leave after one load.
        let lo_d = f.load(s.lo_depth, p).await;
        let behind = z > lo_d || (z == lo_d && f.load(s.lo_prim, p).await < prim);
        if !behind {
            f.discard();
            return;
        }
        let found = f.load(s.found, p).await;
        if found >= s.k {
            f.discard();
            return;
        }
        if f.atomic_add(s.inflight, p, 1).await != 0 {
            f.atomic_or(s.dirty, p, 1).await;
        }
        rmw_insert(f, s.kb, p * s.k + found, (s.k - found) as usize, z, prim).await;
        f.atomic_sub(s.inflight, p, 1).await;
        f.output(0, [z, f32::from_bits(prim), 0.0, 0.0]);
    }
}

/// The full-screen merge: certifies and moves the bound (see the module documentation).
struct Merge<'i> {
    s: State,
    /// The depth test's nearest of this pass (RG32F: depth, primitive bits).
    nearest: &'i Image,
}

impl Merge<'_> {
    async fn bump(&self, f: impl Fragment, which: u32, by: u32) {
        f.atomic_add(self.s.stats, which, by).await;
    }
}

impl FragmentKernel for Merge<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-multipass-merge")
    }
    async fn shade(&self, f: impl Fragment) {
        let s = &self.s;
        let p = f.pixel_index();
        let lo = (f.load(s.lo_depth, p).await, f.load(s.lo_prim, p).await);
        if lo.0 == DONE.0 {
            return;
        }
        let t = f.texel(self.nearest, f.x(), f.y(), 0);
        let near = (f32::from_bits(t[0]), t[1]);
        let found = f.load(s.found, p).await;
        let dirty = f.load(s.dirty, p).await != 0;
        f.store(s.dirty, p, 0).await;
        if near.0 == DONE.0 || found >= s.k {
            // Nothing behind the bound: the pixel has fewer than k fragments, all certified.
            // (`found == k` comes with the `DONE` bound; the test only guards the slices.)
            f.store(s.lo_depth, p, DONE.0).await;
            f.store(s.lo_prim, p, DONE.1).await;
            return;
        }
        if !key_less(lo.0, lo.1, near.0, near.1) {
            self.bump(f, stat::NOT_BEHIND, 1).await;
        }
        let base = p * s.k + found;
        let cap = (s.k - found) as usize;
        let mut d = [f32::INFINITY; MAX_K as usize];
        let mut c = [EMPTY; MAX_K as usize];
        f.load_record(s.kb.depth, base, &mut d[..cap]).await;
        f.load_record(s.kb.prim, base, &mut c[..cap]).await;
        let m = d[..cap].iter().take_while(|&&x| x != f32::INFINITY).count();
        // Sorted strictly, nothing after the first empty, and the nearest is the depth test's:
        // a clean pixel that is not so would mean the clean-pixel argument is wrong.
        let well_formed = m > 0
            && (d[0], c[0]) == near
            && (1..m).all(|i| key_less(d[i - 1], c[i - 1], d[i], c[i]))
            && d[m..cap].iter().all(|&x| x == f32::INFINITY);
        if !dirty {
            self.bump(
                f,
                if well_formed {
                    stat::CLEAN
                } else {
                    stat::CLEAN_DISAGREES
                },
                1,
            )
            .await;
        } else {
            self.bump(f, stat::DIRTY, 1).await;
            if (d[0], c[0]) != near {
                self.bump(f, stat::DIRTY_WRONG_NEAREST, 1).await;
            }
        }
        let (new_found, bound) = if !dirty && well_formed {
            // A clean pixel is complete: its slots are full, or everything behind the bound fit.
            (found + m as u32, DONE)
        } else {
            // Keep only the depth test's nearest: write it, clear the racy rest.
            d[0] = near.0;
            c[0] = near.1;
            d[1..cap].fill(f32::INFINITY);
            c[1..cap].fill(EMPTY);
            f.store_record(s.kb.depth, base, &d[..cap]).await;
            f.store_record(s.kb.prim, base, &c[..cap]).await;
            (found + 1, near)
        };
        let bound = if new_found == s.k { DONE } else { bound };
        f.store(s.found, p, new_found).await;
        f.store(s.lo_depth, p, bound.0).await;
        f.store(s.lo_prim, p, bound.1).await;
        self.bump(f, stat::CERTIFIED, new_found - found).await;
        if bound.0 != DONE.0 {
            self.bump(f, stat::ACTIVE, 1).await;
        }
    }
}

/// `kb-multipass`: see the module documentation.
pub struct KbMultipass;

impl Algorithm for KbMultipass {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "kb-multipass",
            family: "k-buffer",
            summary: "multipass k-buffer: each pass runs the racy k-buffer behind the last certified fragment and \
                      keeps what is certainly correct (the depth test's nearest; everything where no insertions \
                      overlapped); races cost passes, never fragments",
            source: "Liu, Wei, Xu, Wu, multi-layer depth peeling via fragment sort (MSR-TR-2006-81, CAD/Graphics \
                     2009); depth-fighting paper [19], section 2 and Table 1 (MultiKB); bucket-depth-peeling \
                     paper, section 2",
            passes: "1 to k geometry, each followed by 1 full-screen merge; + 1 full-screen resolve",
            memory: "8 k + 20 bytes: k depths + k primitive ids + bound (depth, primitive), certified count, \
                     in-flight and dirty words (Table 1, MultiKB: 3K + 2 words); + 12 bytes of depth and RG32F \
                     target; + 16-byte resolve target",
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
        let mut run = KbRun::new(frame, params, exec)?;
        let n = run.n as u64;
        let kb = SplitSlots::new(&mut run.device, run.n, run.k)?;
        let s = State {
            kb,
            k: run.k,
            lo_depth: run.device.buffer::<f32>("kb-mp-bound-depth", n)?,
            lo_prim: run.device.buffer::<u32>("kb-mp-bound-prim", n)?,
            found: run.device.buffer::<u32>("kb-mp-found", n)?,
            inflight: run.device.buffer::<u32>("kb-mp-inflight", n)?,
            dirty: run.device.buffer::<u32>("kb-mp-dirty", n)?,
            stats: run.device.buffer::<u32>("kb-mp-stats", stat::COUNT)?,
        };
        run.device.memory.fill(s.lo_depth, f32::NEG_INFINITY)?;

        let mut fb = framebuffer(frame, SampleCount::X1, &[Format::RG32F])?;
        let mut capture_state = crate::common::capture_state();
        capture_state.fragment.depth = DepthState {
            test: true,
            func: CompareFunc::Less,
            write: true,
        };
        capture_state.fragment.early = EarlyTests::ForceLate;
        capture_state.fragment.targets = vec![TargetState::new(Format::RG32F)];
        let merge_state = FragmentState::new();

        let mut report = fragrace_emu::PassReport::default();
        let mut passes = 0;
        let mut active = u32::MAX;
        let mut per_pass = Vec::new();
        while active > 0 && passes < run.k {
            // Depth cleared past any fragment (1.0 is a valid depth), target to "none".
            fb.clear_depth(f32::INFINITY);
            fb.clear_color(0, [f32::INFINITY.to_bits(), EMPTY, 0, 0]);
            report.merge(&geometry_pass(
                &run.device,
                &mut fb,
                frame,
                &capture_state,
                &Capture { s },
                exec,
            )?);
            let nearest = fb.image(0);
            run.device
                .memory
                .write(s.stats, stat::ACTIVE as u64, &[0])?;
            let before = run.device.memory.read(s.stats)?[stat::CERTIFIED as usize];
            let mut merge_fb = framebuffer(frame, SampleCount::X1, &[])?;
            report.merge(&run.device.fullscreen(
                &mut merge_fb,
                &merge_state,
                &Merge {
                    s,
                    nearest: &nearest,
                },
                exec,
            )?);
            let st = run.device.memory.read(s.stats)?;
            active = st[stat::ACTIVE as usize];
            per_pass.push(st[stat::CERTIFIED as usize] - before);
            passes += 1;
        }

        let st = run.device.memory.read(s.stats)?;
        let slots = Slots::Split(kb);
        let shape = Shape::of(&slots.read(&run.device, run.k)?, true, None);
        let h = report.hazards;
        let checks = vec![
            shape.check(frame.width, false),
            Check::new(
                "each pass's depth-test nearest is strictly behind the last certified fragment",
                st[stat::NOT_BEHIND as usize] == 0,
                format!("{} violations", st[stat::NOT_BEHIND as usize]),
            ),
            Check::new(
                "clean pixels: the k-buffer is sorted and its nearest is the depth test's",
                st[stat::CLEAN_DISAGREES as usize] == 0,
                format!("{} disagreements", st[stat::CLEAN_DISAGREES as usize]),
            ),
            Check::new(
                "progress: every pixel finished within k geometry passes",
                active == 0,
                format!("{passes} passes (k = {}), {active} pixels still active", run.k),
            ),
            Check::new(
                "races absorbed (informational)",
                true,
                format!(
                    "certified per pass {per_pass:?}; pixel-passes clean {}, dirty {} (nearest slot corrupted in {}); \
                     detector: lost updates {}, races {}, torn {}",
                    st[stat::CLEAN as usize],
                    st[stat::DIRTY as usize],
                    st[stat::DIRTY_WRONG_NEAREST as usize],
                    h.lost_updates,
                    h.races,
                    h.torn
                ),
            ),
        ];
        // Depth (4) and RG32F (8) bytes per pixel of the capture passes.
        run.finish(slots, report, checks, 0, 12)
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{ExecConfig, Policy};

    use super::super::rmw::KbRmw;
    use super::*;
    use crate::testing::*;

    fn passes(r: &AlgoResult) -> u64 {
        r.report.stats.geometry_passes as u64
    }

    #[test]
    fn exact_under_every_executor() {
        assert_exact_everywhere(&KbMultipass, &Params::default(), 3);
    }

    #[test]
    fn one_pass_when_nothing_races() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        let (r, m) = run(
            &KbMultipass,
            &frame,
            &Params::default(),
            &ExecConfig::ordered(),
        );
        assert_eq!(m.error_pixels, 0);
        assert_eq!(
            passes(&r),
            1,
            "serial insertions are all clean: {:?}",
            r.checks
        );
    }

    #[test]
    fn races_cost_passes_not_fragments() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        let params = Params::default();
        for seed in 0..3 {
            let exec = scheduled(Policy::Random, seed);
            let (racy, racy_m) = run(&KbRmw, &frame, &params, &exec);
            assert!(
                racy_m.error_pixels > 0,
                "the single-pass k-buffer loses fragments here"
            );
            let (r, m) = run(&KbMultipass, &frame, &params, &exec);
            assert_eq!(m.error_pixels, 0, "seed {seed}");
            assert!(
                passes(&r) > 1 && passes(&r) <= params.k as u64,
                "seed {seed}: {} passes",
                passes(&r)
            );
            assert!(
                r.report.hazards.lost_updates > 0,
                "the capture still races: {:?}",
                racy.report.hazards
            );
            assert_checks(&r, "random");
        }
    }

    #[test]
    fn every_k() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        for k in [1, 2, 5, 16, 20] {
            let params = Params {
                k,
                ..Params::default()
            };
            for exec in [
                ExecConfig::ordered(),
                scheduled(Policy::Pct { depth: 3 }, k as u64),
            ] {
                let (r, m) = run(&KbMultipass, &frame, &params, &exec);
                assert_eq!(
                    m.error_pixels, 0,
                    "k = {k}: first error {:?}",
                    m.first_error
                );
                assert_checks(&r, &format!("k = {k}"));
                assert!(passes(&r) <= k as u64);
            }
        }
    }
}
