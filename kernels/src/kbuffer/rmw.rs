//! `kb-rmw`: the original k-buffer (Bavoil et al. 2007, "Multi-fragment effects on the GPU
//! using the k-buffer", cited as \[17\] by the depth-fighting paper, section 2 and Table 1 row
//! KB; the llvmpipe peer's `kbuf-rmw`), and the pieces the other k-buffers of this folder
//! that keep `(depth, primitive)` slots share with it: the slot layout, the sorted
//! read-modify-write insertion, the full-screen resolve, the readback and the slot-shape
//! invariants.
//!
//! Each pixel owns k depth slots (`+inf` = empty) and k primitive slots (`EMPTY`). A fragment
//! plain-loads its pixel's k slots, inserts itself by sorted insertion if it is nearer than
//! the farthest, and plain-stores all k back. Two fragments of one pixel in flight together
//! read the same slots and the second store overwrites the first: the read-modify-write
//! hazard (RMWH) every seed names (bucket-depth-peeling paper, section 2; depth-fighting
//! paper, section 2; occupancy paper, section 1). Run one fragment at a time (`ordered`) it is
//! exact.

use fragrace_emu::{
    Buf, Device, ExecConfig, Fragment, FragmentKernel, Framebuffer, KernelInfo, PassReport,
    SampleCount,
};

use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Capture, CapturedFrag, Check, Frame,
    HazardClass, Params,
};
use crate::common::{
    self, capture_state, framebuffer, geometry_pass, pixels, sort_fragments, EMPTY,
};
use crate::occupancy::Culling;
use crate::resolve::{self, Composite};

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(KbRmw)]
}

/// Largest k the k-buffers accept: a kernel keeps its pixel's slots in fixed local arrays,
/// as a shader keeps them in registers (the seeds use k <= 32 with packing, Table 1).
pub(super) const MAX_K: u32 = 64;

/// `params.k`, checked against `1..=MAX_K`.
pub(super) fn k_of(params: &Params) -> Result<u32, AlgoError> {
    if params.k == 0 || params.k > MAX_K {
        Err(AlgoError::Invalid(format!(
            "k = {} is outside 1..={MAX_K}",
            params.k
        )))
    } else {
        Ok(params.k)
    }
}

/// The order of k-buffer slots: depth, then primitive id (the truth's order). Breaking
/// ties by primitive (rather than by arrival, as Bavoil's depth-only compare does) makes the
/// kept set of a serial run independent of arrival order even with coplanar fragments
/// (depth-fighting paper, section 1), and it is what lets `kb-multipass` resume exactly
/// behind a certified fragment.
pub(super) fn key_less(ad: f32, ap: u32, bd: f32, bp: u32) -> bool {
    ad < bd || (ad == bd && ap < bp)
}

/// k depth slots and k primitive slots per pixel, pixel `p`'s at `p * k ..`.
#[derive(Clone, Copy, Debug)]
pub struct SplitSlots {
    pub depth: Buf<f32>,
    pub prim: Buf<u32>,
}

impl SplitSlots {
    /// Allocates and clears (`+inf` / `EMPTY`) the slots of `pixels` pixels.
    pub fn new(device: &mut Device, pixels: usize, k: u32) -> Result<SplitSlots, AlgoError> {
        let len = pixels as u64 * k as u64;
        let depth = device.buffer::<f32>("kb-depth", len)?;
        let prim = device.buffer::<u32>("kb-prim", len)?;
        device.memory.fill(depth, f32::INFINITY)?;
        device.memory.fill(prim, EMPTY)?;
        Ok(SplitSlots { depth, prim })
    }
}

/// Bavoil's insertion on the `cap` slots at `base`, with plain accesses only: load them all
/// (two multi-word records, so the detector reports a load torn by another fragment's
/// store), sorted insertion if `(z, prim)` is nearer than the farthest (which falls out),
/// store them all back. Returns whether it inserted. Correct only if no other fragment of the
/// pixel touches the slots meanwhile (a serial run, a lock, or pixel interlock).
pub(super) async fn rmw_insert(
    f: impl Fragment,
    kb: SplitSlots,
    base: u32,
    cap: usize,
    z: f32,
    prim: u32,
) -> bool {
    let mut d = [f32::INFINITY; MAX_K as usize];
    let mut c = [EMPTY; MAX_K as usize];
    let cap = cap.clamp(1, MAX_K as usize);
    f.load_record(kb.depth, base, &mut d[..cap]).await;
    f.load_record(kb.prim, base, &mut c[..cap]).await;
    if !key_less(z, prim, d[cap - 1], c[cap - 1]) {
        return false;
    }
    let mut j = cap - 1;
    while j > 0 && key_less(z, prim, d[j - 1], c[j - 1]) {
        d[j] = d[j - 1];
        c[j] = c[j - 1];
        j -= 1;
    }
    d[j] = z;
    c[j] = prim;
    f.store_record(kb.depth, base, &d[..cap]).await;
    f.store_record(kb.prim, base, &c[..cap]).await;
    true
}

/// Where a k-buffer keeps its k slots per pixel, for the shared resolve and readback.
#[derive(Clone, Copy, Debug)]
pub(super) enum Slots {
    /// Depth (`+inf` = empty) and primitive id, in two buffers.
    Split(SplitSlots),
    /// 32-bit keys (f32 depth bits, `EMPTY` = empty) and the primitive id that claimed each.
    Key32 { key: Buf<u32>, prim: Buf<u32> },
    /// 64-bit keys `depth bits << 32 | primitive id` (`u64::MAX` = empty).
    Key64 { key: Buf<u64> },
}

impl Slots {
    /// Slot `i` as a kernel reads it (plain loads); `None` when empty.
    async fn load(&self, f: impl Fragment, i: u32) -> Option<CapturedFrag> {
        match *self {
            Slots::Split(s) => {
                let depth = f.load(s.depth, i).await;
                let prim = f.load(s.prim, i).await;
                (depth != f32::INFINITY).then_some(CapturedFrag { depth, prim })
            }
            Slots::Key32 { key, prim } => {
                let k = f.load(key, i).await;
                let prim = f.load(prim, i).await;
                (k != EMPTY).then_some(CapturedFrag::from_bits(k, prim))
            }
            Slots::Key64 { key } => {
                let k = f.load(key, i).await;
                (k != u64::MAX).then(|| unpack64(k))
            }
        }
    }

    /// Every slot, read back on the host, per pixel in slot order.
    pub(super) fn read(
        &self,
        device: &Device,
        k: u32,
    ) -> Result<Vec<Vec<Option<CapturedFrag>>>, AlgoError> {
        let flat: Vec<Option<CapturedFrag>> = match *self {
            Slots::Split(s) => {
                let d = device.memory.read(s.depth)?;
                let p = device.memory.read(s.prim)?;
                d.iter()
                    .zip(&p)
                    .map(|(&depth, &prim)| {
                        (depth != f32::INFINITY).then_some(CapturedFrag { depth, prim })
                    })
                    .collect()
            }
            Slots::Key32 { key, prim } => {
                let d = device.memory.read(key)?;
                let p = device.memory.read(prim)?;
                d.iter()
                    .zip(&p)
                    .map(|(&k, &prim)| (k != EMPTY).then_some(CapturedFrag::from_bits(k, prim)))
                    .collect()
            }
            Slots::Key64 { key } => device
                .memory
                .read(key)?
                .into_iter()
                .map(|k| (k != u64::MAX).then(|| unpack64(k)))
                .collect(),
        };
        Ok(flat.chunks(k as usize).map(<[_]>::to_vec).collect())
    }
}

/// The 64-bit key of a fragment: depth bits in the high word (order-preserving for
/// depth >= 0), primitive id in the low word (unique per pixel, so keys never tie).
pub(super) fn pack64(depth: f32, prim: u32) -> u64 {
    ((depth_key(depth) as u64) << 32) | prim as u64
}

fn unpack64(k: u64) -> CapturedFrag {
    CapturedFrag::from_bits((k >> 32) as u32, k as u32)
}

/// The f32 bits of a depth as an unsigned key. For depth >= 0 the unsigned order of the bits
/// is the float order (IEEE 754 sign-magnitude with a biased exponent), which is what lets
/// `atomicMin` on uint order depths (known hazard, docs/hazards.md: "keys compared as uint assume depth >= 0").
/// `-0.0` is canonicalised to `+0.0` (its bits would sort last); it compares equal to `+0.0`
/// for the oracle. Negative depths cannot come out of the [0, 1] window transform; the
/// atomic k-buffers count any that do and fail a check.
pub(super) fn depth_key(depth: f32) -> u32 {
    (depth + 0.0).to_bits()
}

/// The full-screen resolve every buffer-based method needs (depth-fighting paper, section 2:
/// "an additional fullscreen post-processing pass to sort the captured fragments"; `oit.py`'s
/// `FS_KBUF_RESOLVE`): read the pixel's slots, sort, composite front to back.
struct Resolve {
    slots: Slots,
    k: u32,
    composite: Composite,
}

impl FragmentKernel for Resolve {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-resolve")
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * self.k;
        let mut frags = [CapturedFrag {
            depth: 0.0,
            prim: 0,
        }; MAX_K as usize];
        let mut n = 0;
        for i in 0..self.k {
            if let Some(c) = self.slots.load(f, base + i).await {
                frags[n] = c;
                n += 1;
            }
        }
        sort_fragments(&mut frags[..n]);
        self.composite.output(&f, &frags[..n]);
    }
}

/// One run of a k-buffer: the device, the frame, the parameters and the executor, and the
/// steps every k-buffer of this folder shares (capture pass, resolve, readback, result). The
/// A-buffers' counterpart is `abuffer::run::AbRun`.
pub(super) struct KbRun<'a> {
    pub device: Device,
    pub frame: Frame<'a>,
    pub params: &'a Params,
    pub exec: &'a ExecConfig,
    pub k: u32,
    pub n: usize,
    /// The capture passes' framebuffer (its depth buffer holds the culling bound).
    fb: Option<Framebuffer>,
    /// Occupancy culling, when the parameters ask for it.
    culling: Option<Culling>,
}

impl<'a> KbRun<'a> {
    pub(super) fn new(
        frame: &Frame<'a>,
        params: &'a Params,
        exec: &'a ExecConfig,
    ) -> Result<KbRun<'a>, AlgoError> {
        Ok(KbRun {
            device: common::fresh(exec),
            frame: *frame,
            params,
            exec,
            k: k_of(params)?,
            n: pixels(frame),
            fb: None,
            culling: None,
        })
    }

    /// One capture pass of the frame with `kernel`, every fragment through (no targets), or,
    /// with occupancy culling, every fragment up to its pixel's bound: the first capture
    /// runs the culling stage. The report is the capture pass's alone (the stage's passes
    /// join the result in [`KbRun::finish`]), so the algorithm's checks see its own pass.
    pub(super) fn capture<K: FragmentKernel>(
        &mut self,
        kernel: &K,
    ) -> Result<PassReport, AlgoError> {
        let fb = match &mut self.fb {
            Some(fb) => fb,
            None => {
                let mut fb = framebuffer(&self.frame, SampleCount::X1, &[])?;
                self.culling = Culling::prepare(
                    &mut self.device,
                    &mut fb,
                    &self.frame,
                    self.params,
                    self.exec,
                )?;
                self.fb.insert(fb)
            }
        };
        let state = match self.culling {
            Some(_) => Culling::peel_state(&capture_state()),
            None => capture_state(),
        };
        let report = geometry_pass(&self.device, fb, &self.frame, &state, kernel, self.exec)?;
        if let Some(c) = &mut self.culling {
            c.add_peel(&report);
        }
        Ok(report)
    }

    /// The sum of a per-pixel counter buffer (the instrumentation counts of the invariants).
    pub(super) fn total(&self, counter: Buf<u32>) -> Result<u64, AlgoError> {
        Ok(self
            .device
            .memory
            .read(counter)?
            .iter()
            .map(|&c| c as u64)
            .sum())
    }

    /// Resolves `slots` with the full-screen kernel (the image), reads them back (the
    /// capture: what the buffers hold, sorted front to back) and assembles the result.
    /// `target_bytes` are the per-pixel bytes of render targets of earlier passes.
    pub(super) fn finish(
        self,
        slots: Slots,
        mut report: PassReport,
        checks: Vec<Check>,
        dropped: u64,
        target_bytes: u64,
    ) -> Result<AlgoResult, AlgoError> {
        let mut fb = resolve::framebuffer(&self.frame)?;
        let kernel = Resolve {
            slots,
            k: self.k,
            composite: Composite::of(self.params),
        };
        report.merge(&resolve::pass(&self.device, &mut fb, &kernel, self.exec)?);
        let image = resolve::read_image(&fb);
        // The culling stage's depth buffer (4 bytes a pixel) is storage too.
        let culling = self.culling.map(|c| {
            let (stage, summary) = c.finish();
            report.merge(&stage);
            summary
        });
        let depth_bytes = if culling.is_some() { 4 } else { 0 };
        let lists = slots.read(&self.device, self.k)?.into_iter().map(|l| {
            let mut v: Vec<CapturedFrag> = l.into_iter().flatten().collect();
            sort_fragments(&mut v);
            v
        });
        let capture = Capture::from_lists(self.frame.width, self.frame.height, lists);
        Ok(AlgoResult {
            capture: Some(capture),
            image: Some(image),
            report,
            checks,
            dropped,
            storage_bytes: self.device.memory.bytes()
                + self.n as u64 * (target_bytes + depth_bytes + resolve::TARGET_BYTES),
            culling,
            ..Default::default()
        })
    }
}

/// The shape of a pixel's slots after the passes, tallied over pixels.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Shape {
    /// Pixels whose occupied slots are not in ascending order.
    pub unsorted: u64,
    /// Pixels with an empty slot before an occupied one.
    pub gaps: u64,
    /// Pixels holding the same `(depth, primitive)` twice (a fragment counted twice).
    pub duplicates: u64,
    /// Pixels whose occupied slots are not `min(k, fragments)` (when counts are known).
    pub wrong_count: u64,
    pub first_bad: Option<usize>,
}

impl Shape {
    /// Tallies `raw` (slots per pixel, in slot order). `by_prim`: slots are ordered by
    /// `(depth, primitive)`; otherwise by depth only (primitives attached afterwards).
    /// `counts`: fragments per pixel, to check that exactly `min(k, n)` slots are occupied.
    pub(super) fn of(
        raw: &[Vec<Option<CapturedFrag>>],
        by_prim: bool,
        counts: Option<&[u32]>,
    ) -> Shape {
        let mut s = Shape::default();
        for (p, slots) in raw.iter().enumerate() {
            let mut bad = false;
            let occupied: Vec<CapturedFrag> = slots.iter().flatten().copied().collect();
            if slots.windows(2).any(|w| w[0].is_none() && w[1].is_some()) {
                s.gaps += 1;
                bad = true;
            }
            let out_of_order = occupied.windows(2).any(|w| {
                if by_prim {
                    key_less(w[1].depth, w[1].prim, w[0].depth, w[0].prim)
                } else {
                    w[1].depth < w[0].depth
                }
            });
            if out_of_order {
                s.unsorted += 1;
                bad = true;
            }
            let mut sorted = occupied.clone();
            sorted.sort_by(common::depth_order);
            if sorted
                .windows(2)
                .any(|w| w[0].depth == w[1].depth && w[0].prim == w[1].prim && w[0].prim != EMPTY)
            {
                s.duplicates += 1;
                bad = true;
            }
            if let Some(c) = counts {
                if occupied.len() != (c[p] as usize).min(slots.len()) {
                    s.wrong_count += 1;
                    bad = true;
                }
            }
            if bad && s.first_bad.is_none() {
                s.first_bad = Some(p);
            }
        }
        s
    }

    pub(super) fn ok(&self) -> bool {
        self.unsorted == 0 && self.gaps == 0 && self.duplicates == 0 && self.wrong_count == 0
    }

    pub(super) fn detail(&self, width: u32) -> String {
        let first = match self.first_bad {
            Some(p) => format!("; first at ({}, {})", p as u32 % width, p as u32 / width),
            None => String::new(),
        };
        format!(
            "pixels unsorted {}, with gaps {}, with a fragment twice {}, with a wrong slot count {}{first}",
            self.unsorted, self.gaps, self.duplicates, self.wrong_count
        )
    }

    /// The check "slots sorted, no gaps, no fragment twice (and min(k, n) occupied)".
    pub(super) fn check(&self, width: u32, counted: bool) -> Check {
        let name = if counted {
            "slots sorted ascending, empties last, no fragment twice, min(k, n) occupied"
        } else {
            "slots sorted ascending, empties last, no fragment twice"
        };
        Check::new(name, self.ok(), self.detail(width))
    }
}

/// The read-modify-write capture kernel (Bavoil et al. 2007; `oit.py`'s
/// `FS_KBUF_RMW`).
pub struct RmwStore {
    pub kb: SplitSlots,
    pub k: u32,
}

impl FragmentKernel for RmwStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("kb-rmw-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let base = f.pixel_index() * self.k;
        rmw_insert(
            f,
            self.kb,
            base,
            self.k as usize,
            f.depth(),
            f.primitive_id(),
        )
        .await;
    }
}

/// `kb-rmw`: see the module documentation.
pub struct KbRmw;

impl Algorithm for KbRmw {
    /// Its capture passes run through `KbRun::capture`, which puts them behind occupancy
    /// culling when asked.
    fn takes_occupancy(&self) -> bool {
        true
    }
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "kb-rmw",
            family: "k-buffer",
            summary: "the original k-buffer: plain load of the k slots, sorted insertion, plain store of all k \
                      (read-modify-write hazard by design)",
            source: "Bavoil et al. 2007 (I3D); depth-fighting paper [17], section 2 and Table 1 (KB); \
                     llvmpipe peer `kbuf-rmw`",
            passes: "1 geometry + 1 full-screen (resolve)",
            memory: "8 k bytes: k depths + k primitive ids (Table 1, KB: 2K + 2 words with the colour and depth \
                     targets); + 16-byte resolve target",
            hazard: HazardClass::HazardProne,
            capacity: Capacity::KNearest,
        }
    }

    fn run(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut run = KbRun::new(frame, params, exec)?;
        let kb = SplitSlots::new(&mut run.device, run.n, run.k)?;
        let report = run.capture(&RmwStore { kb, k: run.k })?;
        let slots = Slots::Split(kb);
        let shape = Shape::of(&slots.read(&run.device, run.k)?, true, None);
        // Racing is this algorithm's documented behaviour, not a broken invariant: the
        // symptoms are reported as information (what the hazard did to the slots).
        let h = report.hazards;
        let checks = vec![
            Check::new(
                "slot corruption by races (informational)",
                true,
                shape.detail(frame.width),
            ),
            Check::new(
                "hazards seen by the detector (informational)",
                true,
                format!(
                    "lost updates {}, races {}, torn records {}",
                    h.lost_updates, h.races, h.torn
                ),
            ),
        ];
        run.finish(slots, report, checks, 0, 0)
    }
}

/// Scenes, executors and the oracle comparison shared by the k-buffer tests of this folder.
#[cfg(test)]
pub(crate) mod testing {
    use fragrace_emu::{ExecConfig, ExecMode, Mesh, Policy, ScheduleConfig};
    use glam::Vec3;

    use crate::algo::{AlgoResult, Algorithm, Frame, Params};
    use crate::basic::Truth;
    use crate::oracle::{self, Metrics};

    /// At 8 x 8 pixels the RMW k-buffer under a random schedule has an EPR of about 0.6; at
    /// 16 x 16, about 0.04 (fewer fragments of one pixel in the scheduler's window at once).
    ///
    /// `n` overlapping axis-aligned quads at constant depths in a shuffled (not depth)
    /// order, each offset a little so that depth complexity varies from pixel to pixel, plus
    /// an exact duplicate of quad 0 (coplanar fragments, depth-fighting paper section 1) and
    /// two quads sharing one depth. Identity view-projection: NDC = clip.
    pub fn quads(n: usize) -> Mesh {
        let mut m = Mesh::default();
        let mut quad = |x0: f32, y0: f32, x1: f32, y1: f32, z: f32| {
            let b = m.positions.len() as u32;
            m.positions.extend([
                Vec3::new(x0, y0, z),
                Vec3::new(x1, y0, z),
                Vec3::new(x1, y1, z),
                Vec3::new(x0, y1, z),
            ]);
            m.indices.push([b, b + 1, b + 2]);
            m.indices.push([b, b + 2, b + 3]);
        };
        for i in 0..n {
            // A permutation of the depth levels (7 is coprime with every power of two).
            let level = (i * 7 + 3) % n.max(1);
            let z = -0.8 + 1.6 * level as f32 / n as f32;
            let o = (i % 5) as f32 * 0.08;
            let p = (i % 3) as f32 * 0.1;
            quad(-0.9 + o, -0.85 + p, 0.55 + o * 0.5, 0.7 - p, z);
        }
        // Coplanar: a duplicate of quad 0, and a quad at quad 1's depth.
        let z0 = -0.8 + 1.6 * (3 % n.max(1)) as f32 / n as f32;
        quad(-0.9, -0.85, 0.55, 0.7, z0);
        let z1 = -0.8 + 1.6 * ((7 + 3) % n.max(1)) as f32 / n as f32;
        quad(-0.3, -0.5, 0.9, 0.9, z1);
        m
    }

    /// `mesh` at `size` x `size` pixels.
    pub fn frame(mesh: &Mesh, size: u32) -> Frame<'_> {
        crate::test_scenes::frame(mesh, size, size)
    }

    /// Scheduled executor with `policy`, `seed` and the default window.
    pub fn scheduled(policy: Policy, seed: u64) -> ExecConfig {
        ExecConfig::scheduled(policy, seed)
    }

    /// Ordered, parallel(2), parallel(4) with small batches (fragments of one pixel on
    /// different threads), parallel(3) with lanes run to completion instead of in lockstep,
    /// and scheduled under every policy with `seeds` seeds each, plus lockstep forward
    /// progress (`simt`) and a wide window.
    pub fn executors(seeds: u64) -> Vec<(String, ExecConfig)> {
        let mut v = vec![
            ("ordered".to_string(), ExecConfig::ordered()),
            ("parallel(2)".to_string(), ExecConfig::parallel(2)),
            (
                "parallel(4) batch 8".to_string(),
                ExecConfig {
                    batch: 8,
                    ..ExecConfig::parallel(4)
                },
            ),
            (
                "parallel(3) without lockstep".to_string(),
                ExecConfig {
                    lockstep: false,
                    ..ExecConfig::parallel(3)
                },
            ),
        ];
        for policy in Policy::all() {
            for seed in 0..seeds {
                v.push((
                    format!("scheduled {policy} seed {seed}"),
                    scheduled(policy.clone(), seed),
                ));
            }
        }
        // Lockstep forward progress: spinning lanes hold their warp-mates back.
        v.push((
            "scheduled random simt 32".to_string(),
            ExecConfig {
                simt: 32,
                ..scheduled(Policy::Random, 0)
            },
        ));
        // A wide window: more fragments of one pixel in flight at once.
        v.push((
            "scheduled random window 256".to_string(),
            ExecConfig {
                mode: ExecMode::Scheduled(ScheduleConfig {
                    window: 256,
                    ..Default::default()
                }),
                ..ExecConfig::default()
            },
        ));
        v
    }

    /// Runs `algo` and compares it with the truth.
    pub fn run(
        algo: &dyn Algorithm,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> (AlgoResult, Metrics) {
        let result = algo.run(frame, params, exec).expect("the algorithm runs");
        let truth = Truth::capture(frame, 1).expect("truth runs");
        let m = oracle::compare(&algo.info(), &result, &truth, params);
        (result, m)
    }

    /// Asserts that every check of `r` passed.
    pub fn assert_checks(r: &AlgoResult, what: &str) {
        for c in &r.checks {
            assert!(c.passed, "{what}: check `{}` failed: {}", c.name, c.detail);
        }
        assert_eq!(
            r.report.stats.faulted, 0,
            "{what}: faults {:?}",
            r.report.faults
        );
    }

    /// Runs a hazard-free algorithm under every executor: EPR 0, checks pass, no faults, and
    /// the resolve's image is the composite of the capture.
    /// Two sizes of the 16-quad scene: 8 x 8 (every pixel's fragments in flight together)
    /// and 16 x 16 (more pixels, varied depth complexity).
    pub fn assert_exact_everywhere(algo: &dyn Algorithm, params: &Params, seeds: u64) {
        let mesh = quads(16);
        for (size, (what, exec)) in [8, 16]
            .into_iter()
            .flat_map(|s| executors(seeds).into_iter().map(move |e| (s, e)))
        {
            let frame = frame(&mesh, size);
            let (r, m) = run(algo, &frame, params, &exec);
            let what = format!("{} at {size} x {size} under {what}", algo.info().name);
            assert!(m.covered_pixels > 0, "{what}: the scene covers pixels");
            assert_eq!(
                m.error_pixels, 0,
                "{what}: EPR {} (first error at {:?})",
                m.epr, m.first_error
            );
            assert_checks(&r, &what);
            assert_image_matches_capture(&r, params, &what);
        }
    }

    /// The full-screen resolve's image equals the host composite of the read-back capture.
    pub fn assert_image_matches_capture(r: &AlgoResult, params: &Params, what: &str) {
        let c = r.capture.as_ref().expect("capture");
        let img = r.image.as_ref().expect("image");
        assert_eq!(img.len(), c.pixels(), "{what}: one texel per pixel");
        for (p, &got) in img.iter().enumerate() {
            let want = crate::common::composite_frags(c.pixel(p), params.alpha, params.background);
            assert_eq!(
                got, want,
                "{what}: resolve image differs from the capture at pixel {p}"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{ExecConfig, Policy};

    use super::testing::*;
    use super::*;

    #[test]
    fn exact_when_run_in_order() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        for k in [1, 4, 8, 16] {
            let params = Params {
                k,
                ..Params::default()
            };
            let (r, m) = run(&KbRmw, &frame, &params, &ExecConfig::ordered());
            assert_eq!(
                m.error_pixels, 0,
                "k = {k}: first error {:?}",
                m.first_error
            );
            assert_eq!(r.report.hazards.total(), 0);
            assert_image_matches_capture(&r, &params, "ordered");
        }
    }

    #[test]
    fn loses_fragments_when_fragments_of_a_pixel_race() {
        let mesh = quads(16);
        let frame = frame(&mesh, 16);
        let params = Params::default();
        let mut wrong_runs = 0;
        for seed in 0..4 {
            let (r, m) = run(&KbRmw, &frame, &params, &scheduled(Policy::Random, seed));
            assert!(
                r.report.hazards.lost_updates > 0,
                "seed {seed}: the detector sees lost updates"
            );
            assert!(
                r.report.hazards.races > 0,
                "seed {seed}: the detector sees races"
            );
            if m.error_pixels > 0 {
                wrong_runs += 1;
            }
            assert!(m.robustness <= 1.0);
        }
        assert_eq!(
            wrong_runs, 4,
            "every random schedule loses fragments somewhere (EPR > 0)"
        );
    }

    #[test]
    fn loses_fragments_in_lockstep_warps() {
        // At 8 x 8 a warp of 64 fragments holds fragments of one pixel from consecutive
        // quads, whose lanes interleave at every access whatever the threads do.
        let mesh = quads(16);
        let frame = frame(&mesh, 8);
        let (_, m) = run(&KbRmw, &frame, &Params::default(), &ExecConfig::parallel(2));
        assert!(
            m.error_pixels > 0,
            "parallel lockstep warps lose fragments too"
        );
    }

    #[test]
    fn rejects_bad_k() {
        let mesh = quads(2);
        let frame = frame(&mesh, 8);
        for k in [0, MAX_K + 1] {
            let params = Params {
                k,
                ..Params::default()
            };
            assert!(matches!(
                KbRmw.run(&frame, &params, &ExecConfig::ordered()),
                Err(AlgoError::Invalid(_))
            ));
        }
    }

    #[test]
    fn depth_keys_keep_the_float_order() {
        let ds = [0.0f32, -0.0, 1e-30, 0.25, 0.5, 0.5000001, 0.999, 1.0];
        for a in ds {
            for b in ds {
                assert_eq!(depth_key(a) < depth_key(b), a < b, "{a} vs {b}");
            }
            let c = unpack64(pack64(a, 7));
            assert_eq!((c.depth, c.prim), (a + 0.0, 7));
        }
    }

    #[test]
    fn shape_flags_corruption() {
        let f = |d: f32, p: u32| Some(CapturedFrag { depth: d, prim: p });
        let good = vec![vec![f(0.1, 1), f(0.2, 0), None]];
        assert!(Shape::of(&good, true, Some(&[2])).ok());
        assert_eq!(Shape::of(&good, true, Some(&[1])).wrong_count, 1);
        assert_eq!(
            Shape::of(&[vec![f(0.2, 1), f(0.1, 0), None]], true, None).unsorted,
            1
        );
        assert_eq!(
            Shape::of(&[vec![f(0.1, 1), None, f(0.2, 0)]], true, None).gaps,
            1
        );
        assert_eq!(
            Shape::of(&[vec![f(0.1, 1), f(0.1, 1), None]], true, None).duplicates,
            1
        );
        // Depth-only order accepts primitives in any order at equal depths.
        assert!(Shape::of(&[vec![f(0.1, 5), f(0.1, 2)]], false, None).ok());
    }
}
