//! `dfb`: the dynamic fragment buffer (Maule et al. 2012, "\[MCTB12\]" of the z-thickness paper),
//! and the pieces every count-scan-store A-buffer of this family shares (the count pass, the
//! array resolve, the resolve target, the common checks).
//!
//! DFB as the z-thickness fragment-merging paper uses it (section 4.3, "Unbounded memory usage
//! approach", and section 5.1.2, "Performance analysis"): a **count pass** counts the fragments
//! of every pixel with an atomic add, an **offset table** (the exclusive prefix sum of the
//! counts over all pixels) gives every pixel a contiguous range, a **store pass** puts each
//! fragment at `offset + atomicAdd(fill)` (only an atomic count, no read-modify-write of the
//! fragment data, hence no hazard), and the **resolve pass** sorts each range (insertion sort
//! under 16 fragments, shell sort above, \[VPF15\] as cited in 5.1.2) and composites.
//!
//! The prefix sum runs on the device as three full-screen passes (a reduce-then-scan with rows
//! as blocks, the classic three-phase GPU scan): one invocation per row scans its row, one
//! invocation scans the row totals, then every pixel adds its row's base. Only the total is
//! read back by the host, to allocate the fragment arrays (a GPU would read back the same
//! word, or allocate a worst-case chunk as the z-thickness paper does with N = 1024).

use fragrace_emu::{
    Buf, ExecConfig, Format, Frag, FragmentKernel, FragmentState, Framebuffer, KernelInfo,
    PassReport, SampleCount, TargetState,
};

use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Capture, CapturedFrag, Check, Frame,
    HazardClass, Params,
};
use crate::common::{
    self, capture_state, composite_frags, framebuffer, geometry_pass, pixels, sort_fragments,
};

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(Dfb)]
}

// ------------------------------------------------------------------------------------------
// Shared by the A-buffers of this family.
// ------------------------------------------------------------------------------------------

/// Per-pixel fragment count with an atomic add: the count pass of DFB and SB, and the pass
/// that sizes the linked-list pool exactly (as the llvmpipe peer's `count` pass does).
pub struct CountKernel {
    pub counts: Buf<u32>,
}

impl FragmentKernel for CountKernel {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("abuffer-count")
    }
    async fn shade(&self, f: Frag<'_>) {
        f.atomic_add(self.counts, f.pixel_index(), 1).await;
    }
}

/// Bytes per pixel of the resolve target (one RGBA32F texel).
pub(super) const RESOLVE_TARGET_BYTES: u64 = 16;

/// The framebuffer every pass of an A-buffer runs on: target 0 is the resolve's RGBA32F
/// composite (geometry passes write no target).
pub(super) fn resolve_framebuffer(frame: &Frame<'_>) -> Result<Framebuffer, AlgoError> {
    framebuffer(frame, SampleCount::X1, &[Format::RGBA32F])
}

/// Fixed-function state of a resolve pass: write target 0, no tests, no blending.
pub(super) fn resolve_state() -> FragmentState {
    let mut s = FragmentState::new();
    s.targets = vec![TargetState::new(Format::RGBA32F)];
    s
}

/// Reads the resolve target back as the result image.
pub(super) fn read_image(fb: &Framebuffer) -> Vec<[f32; 4]> {
    fb.image(0)
        .texels
        .iter()
        .map(|t| t.map(f32::from_bits))
        .collect()
}

/// Storage of a run: the device's buffers plus the resolve target.
pub(super) fn storage(device: &fragrace_emu::Device, frame: &Frame<'_>) -> u64 {
    device.memory.bytes() + pixels(frame) as u64 * RESOLVE_TARGET_BYTES
}

/// The resolve kernel wrote, for every pixel, the composite of exactly the fragments the
/// capture holds, in the capture's order (the image and the capture come from the same
/// memory, not one from the other).
pub(super) fn image_check(image: &[[f32; 4]], capture: &Capture, params: &Params) -> Check {
    let mut bad = 0usize;
    let mut first = None;
    for (p, got) in image.iter().enumerate().take(capture.pixels()) {
        let want = composite_frags(capture.pixel(p), params.alpha, params.background);
        if (0..4).any(|c| {
            let d = (got[c] - want[c]).abs();
            d.is_nan() || d > 1e-6
        }) {
            bad += 1;
            first.get_or_insert(p);
        }
    }
    Check::new(
        "resolve image is the composite of the captured fragments",
        bad == 0,
        format!(
            "{bad} pixels differ{}",
            first
                .map(|p| format!(", first at pixel {p}"))
                .unwrap_or_default()
        ),
    )
}

/// No invocation of any pass faulted (out-of-bounds, watchdog, panic).
pub(super) fn fault_check(report: &PassReport) -> Check {
    let first = report
        .faults
        .first()
        .map(|f| format!(": first {f:?}"))
        .unwrap_or_default();
    Check::new(
        "no invocation faulted",
        report.stats.faulted == 0,
        format!("{} faulted{first}", report.stats.faulted),
    )
}

/// The captured fragments of every pixel are in front-to-back order (the resolve sorted them).
pub(super) fn sorted_check(capture: &Capture) -> Check {
    let bad = (0..capture.pixels())
        .filter(|&p| {
            capture
                .pixel(p)
                .windows(2)
                .any(|w| common::depth_order(&w[0], &w[1]).is_gt())
        })
        .count();
    Check::new(
        "resolve order is front to back",
        bad == 0,
        format!("{bad} pixels out of order"),
    )
}

/// No (depth, primitive) pair appears twice in one pixel (a single draw gives each primitive
/// at most one fragment per pixel, so a duplicate means a fragment was stored twice).
pub(super) fn duplicate_check(capture: &Capture) -> Check {
    let mut bad = 0usize;
    let mut first = None;
    for p in 0..capture.pixels() {
        let mut v: Vec<(u32, u32)> = capture
            .pixel(p)
            .iter()
            .map(|f| (f.depth.to_bits(), f.prim))
            .collect();
        v.sort_unstable();
        if v.windows(2).any(|w| w[0] == w[1]) {
            bad += 1;
            first.get_or_insert(p);
        }
    }
    Check::new(
        "no fragment stored twice in a pixel",
        bad == 0,
        format!(
            "{bad} pixels with a duplicate{}",
            first
                .map(|p| format!(", first at pixel {p}"))
                .unwrap_or_default()
        ),
    )
}

/// Covered pixels' ranges `(start, len)` are pairwise disjoint and together cover exactly
/// `[0, total)` (the offset table of a count-scan-store A-buffer).
pub(super) fn ranges_check(ranges: &[(u32, u32)], total: u32) -> Check {
    let mut r: Vec<(u64, u64)> = ranges
        .iter()
        .filter(|r| r.1 > 0)
        .map(|&(s, l)| (s as u64, l as u64))
        .collect();
    r.sort_unstable();
    let mut next = 0u64;
    let mut problem = None;
    for &(s, l) in &r {
        if s != next {
            problem = Some(if s < next {
                format!("range at {s} overlaps the previous one (ending at {next})")
            } else {
                format!("gap [{next}, {s})")
            });
            break;
        }
        next = s + l;
    }
    if problem.is_none() && next != total as u64 {
        problem = Some(format!("ranges end at {next}, total is {total}"));
    }
    Check::new(
        "ranges disjoint and covering [0, total)",
        problem.is_none(),
        problem.unwrap_or_else(|| format!("{} ranges, total {total}", r.len())),
    )
}

/// Where pixel `p`'s fragments live in the fragment arrays.
#[derive(Clone, Copy)]
pub(super) enum Layout {
    /// FAB: `[p * cap, p * cap + min(len, cap))`.
    Fixed { cap: u32 },
    /// DFB: `[offsets[p], offsets[p] + len)`.
    Offsets { offsets: Buf<u32> },
    /// SB: `[group_base[p % groups] + offsets[p], ... + len)` (covered pixels only).
    Grouped {
        offsets: Buf<u32>,
        group_base: Buf<u32>,
        groups: u32,
    },
}

impl Layout {
    async fn base(&self, f: &Frag<'_>, p: u32) -> u32 {
        match *self {
            Layout::Fixed { cap } => p.wrapping_mul(cap),
            Layout::Offsets { offsets } => f.load(offsets, p).await,
            Layout::Grouped {
                offsets,
                group_base,
                groups,
            } => f
                .load(group_base, p % groups)
                .await
                .wrapping_add(f.load(offsets, p).await),
        }
    }
    fn cap(&self) -> u32 {
        match *self {
            Layout::Fixed { cap } => cap,
            _ => u32::MAX,
        }
    }
}

/// The resolve pass of the array A-buffers (FAB, SB, DFB): one invocation per pixel loads its
/// range, sorts it (`sort_fragments`: insertion sort under 16, shell sort above, z-thickness
/// paper 5.1.2), writes it back sorted (so the readback is in resolve order) and outputs the
/// front-to-back composite. Each invocation touches only its own range: hazard-free.
pub(super) struct ArrayResolve {
    pub layout: Layout,
    /// Fragments stored per pixel (clamped to the layout's capacity).
    pub lens: Buf<u32>,
    /// Per-pixel upper bound on `lens` (the counted range), if the layout has no fixed capacity.
    pub limit: Option<Buf<u32>>,
    pub depth: Buf<f32>,
    pub prim: Buf<u32>,
    pub alpha: f32,
    pub background: [f32; 3],
}

impl FragmentKernel for ArrayResolve {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("abuffer-array-resolve")
    }
    async fn shade(&self, f: Frag<'_>) {
        let p = f.pixel_index();
        let mut n = f.load(self.lens, p).await.min(self.layout.cap());
        if let Some(limit) = self.limit {
            n = n.min(f.load(limit, p).await);
        }
        let mut frags = Vec::with_capacity(n as usize);
        if n > 0 {
            let base = self.layout.base(&f, p).await;
            for i in 0..n {
                let depth = f.load(self.depth, base.wrapping_add(i)).await;
                let prim = f.load(self.prim, base.wrapping_add(i)).await;
                frags.push(CapturedFrag { depth, prim });
            }
            sort_fragments(&mut frags);
            for (i, fr) in frags.iter().enumerate() {
                f.store(self.depth, base.wrapping_add(i as u32), fr.depth)
                    .await;
                f.store(self.prim, base.wrapping_add(i as u32), fr.prim)
                    .await;
            }
        }
        f.output(0, composite_frags(&frags, self.alpha, self.background));
    }
}

/// Reads per-pixel ranges `(base, len)` of the fragment arrays back as a capture.
pub(super) fn capture_ranges(
    frame: &Frame<'_>,
    ranges: &[(u32, u32)],
    depth: &[f32],
    prim: &[u32],
) -> Capture {
    let lists = ranges.iter().map(|&(base, len)| {
        let (b, l) = (base as usize, len as usize);
        if l == 0 || b + l > depth.len() {
            return Vec::new();
        }
        depth[b..b + l]
            .iter()
            .zip(&prim[b..b + l])
            .map(|(&depth, &prim)| CapturedFrag { depth, prim })
            .collect()
    });
    Capture::from_lists(frame.width, frame.height, lists)
}

/// Per pixel, the store pass filled exactly what the count pass counted.
pub(super) fn count_store_check(counts: &[u32], fill: &[u32]) -> Check {
    let bad: Vec<usize> = (0..counts.len())
        .filter(|&p| counts[p] != fill[p])
        .collect();
    Check::new(
        "count pass equals store pass (per pixel)",
        bad.is_empty(),
        match bad.first() {
            Some(&p) => format!(
                "{} pixels differ; pixel {p}: counted {}, stored {}",
                bad.len(),
                counts[p],
                fill[p]
            ),
            None => format!(
                "{} fragments in {} pixels",
                counts.iter().map(|&c| c as u64).sum::<u64>(),
                counts.len()
            ),
        },
    )
}

// ------------------------------------------------------------------------------------------
// DFB.
// ------------------------------------------------------------------------------------------

/// Scan phase 1: the invocation at column 0 of each row writes the exclusive prefix sum of
/// its row's counts into `offsets` and the row's total into `row_total[y]` (a row is one
/// scan block; the other invocations of the row have nothing to do).
struct RowScan {
    counts: Buf<u32>,
    offsets: Buf<u32>,
    row_total: Buf<u32>,
}

impl FragmentKernel for RowScan {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-scan-rows")
    }
    async fn shade(&self, f: Frag<'_>) {
        if f.x() != 0 {
            return;
        }
        let row = f.y() * f.width();
        let mut sum = 0u32;
        for x in 0..f.width() {
            let c = f.load(self.counts, row + x).await;
            f.store(self.offsets, row + x, sum).await;
            sum = sum.wrapping_add(c);
        }
        f.store(self.row_total, f.y(), sum).await;
    }
}

/// Scan phase 2: pixel (0, 0) turns the row totals into the rows' exclusive bases, in place,
/// and writes the grand total.
struct RowTotalsScan {
    row_total: Buf<u32>,
    total: Buf<u32>,
}

impl FragmentKernel for RowTotalsScan {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-scan-row-totals")
    }
    async fn shade(&self, f: Frag<'_>) {
        if f.pixel_index() != 0 {
            return;
        }
        let mut sum = 0u32;
        for y in 0..f.height() {
            let t = f.load(self.row_total, y).await;
            f.store(self.row_total, y, sum).await;
            sum = sum.wrapping_add(t);
        }
        f.store(self.total, 0, sum).await;
    }
}

/// Scan phase 3: every pixel adds its row's base to its offset.
struct AddRowBase {
    offsets: Buf<u32>,
    row_base: Buf<u32>,
}

impl FragmentKernel for AddRowBase {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-scan-add")
    }
    async fn shade(&self, f: Frag<'_>) {
        let p = f.pixel_index();
        let base = f.load(self.row_base, f.y()).await;
        let o = f.load(self.offsets, p).await;
        f.store(self.offsets, p, o.wrapping_add(base)).await;
    }
}

/// DFB store pass: slot = `offsets[p] + atomicAdd(fill[p], 1)`. A fragment beyond its
/// pixel's counted range (impossible unless the passes disagree) is dropped and counted
/// rather than written into the neighbour's range.
pub struct DfbStore {
    pub counts: Buf<u32>,
    pub offsets: Buf<u32>,
    pub fill: Buf<u32>,
    pub depth: Buf<f32>,
    pub prim: Buf<u32>,
    pub overflow: Buf<u32>,
}

impl FragmentKernel for DfbStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("dfb-store")
    }
    async fn shade(&self, f: Frag<'_>) {
        let p = f.pixel_index();
        let i = f.atomic_add(self.fill, p, 1).await;
        if i >= f.load(self.counts, p).await {
            f.atomic_add(self.overflow, 0, 1).await;
            return;
        }
        let slot = f.load(self.offsets, p).await.wrapping_add(i);
        f.store(self.depth, slot, f.depth()).await;
        f.store(self.prim, slot, f.primitive_id()).await;
    }
}

/// `dfb`: the dynamic fragment buffer (count, device scan, store, sort-and-composite resolve).
pub struct Dfb;

impl Algorithm for Dfb {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "dfb",
            family: "a-buffer",
            summary: "dynamic fragment buffer: count pass, prefix sum of the counts (3 full-screen passes), \
                      store at offset + atomic fill, resolve sorts (insertion < 16, shell above) and composites",
            source: "Maule et al. 2012 [MCTB12] as used by the z-thickness fragment-merging paper, sections 4.3 and 5.1.2",
            passes: "2 geometry (count, store) + 4 full-screen (3 scan, resolve)",
            memory: "12 + 8 n bytes (count, offset, fill; depth + primitive per fragment), \
                     as SB's 2 C(Zall) + 3 words in Table 1 of the depth-fighting paper",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::All,
        }
    }

    fn run(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let n = pixels(frame);
        let mut device = common::fresh();
        let mut fb = resolve_framebuffer(frame)?;
        let counts = device.buffer::<u32>("dfb-counts", n as u64)?;
        let offsets = device.buffer::<u32>("dfb-offsets", n as u64)?;
        let fill = device.buffer::<u32>("dfb-fill", n as u64)?;
        let row_total = device.buffer::<u32>("dfb-row-totals", frame.height.max(1) as u64)?;
        let total_buf = device.buffer::<u32>("dfb-total", 1)?;
        let overflow = device.buffer::<u32>("dfb-overflow", 1)?;

        let mut report = geometry_pass(
            &device,
            &mut fb,
            frame,
            &capture_state(),
            &CountKernel { counts },
            exec,
        )?;
        let none = FragmentState::new();
        report.merge(&device.fullscreen(
            &mut fb,
            &none,
            &RowScan {
                counts,
                offsets,
                row_total,
            },
            exec,
        )?);
        report.merge(&device.fullscreen(
            &mut fb,
            &none,
            &RowTotalsScan {
                row_total,
                total: total_buf,
            },
            exec,
        )?);
        report.merge(&device.fullscreen(
            &mut fb,
            &none,
            &AddRowBase {
                offsets,
                row_base: row_total,
            },
            exec,
        )?);
        let total = device.memory.read(total_buf)?[0];

        let depth = device.buffer::<f32>("dfb-depth", total.max(1) as u64)?;
        let prim = device.buffer::<u32>("dfb-prim", total.max(1) as u64)?;
        let store = DfbStore {
            counts,
            offsets,
            fill,
            depth,
            prim,
            overflow,
        };
        let stored_report = geometry_pass(&device, &mut fb, frame, &capture_state(), &store, exec)?;
        let generated = stored_report.stats.fragments_generated;
        report.merge(&stored_report);
        let resolve = ArrayResolve {
            layout: Layout::Offsets { offsets },
            lens: fill,
            limit: Some(counts),
            depth,
            prim,
            alpha: params.alpha,
            background: params.background,
        };
        report.merge(&device.fullscreen(&mut fb, &resolve_state(), &resolve, exec)?);

        let counts_v = device.memory.read(counts)?;
        let offsets_v = device.memory.read(offsets)?;
        let fill_v = device.memory.read(fill)?;
        let dropped = device.memory.read(overflow)?[0] as u64;
        let ranges: Vec<(u32, u32)> = (0..n)
            .map(|p| (offsets_v[p], fill_v[p].min(counts_v[p])))
            .collect();
        let capture = capture_ranges(
            frame,
            &ranges,
            &device.memory.read(depth)?,
            &device.memory.read(prim)?,
        );
        let image = read_image(&fb);
        let stored = capture.frags.len() as u64;
        let counted_ranges: Vec<(u32, u32)> = (0..n).map(|p| (offsets_v[p], counts_v[p])).collect();
        let checks = vec![
            count_store_check(&counts_v, &fill_v),
            ranges_check(&counted_ranges, total),
            Check::new(
                "every generated fragment stored exactly once",
                stored + dropped == generated && dropped == 0,
                format!("stored {stored}, dropped {dropped}, generated {generated}"),
            ),
            duplicate_check(&capture),
            sorted_check(&capture),
            image_check(&image, &capture, params),
            fault_check(&report),
        ];
        Ok(AlgoResult {
            capture: Some(capture),
            image: Some(image),
            storage_bytes: storage(&device, frame),
            report,
            checks,
            dropped,
            ..Default::default()
        })
    }
}

/// Scenes and assertions shared by this family's unit tests.
#[cfg(test)]
pub(super) mod test_support {
    use fragrace_emu::{ExecConfig, Mesh, Policy};
    use glam::{Mat4, Vec3};

    use crate::algo::{AlgoResult, Algorithm, Frame, Params};
    use crate::basic::Truth;
    use crate::oracle;

    /// Appends a quad over NDC `[x0, x1] x [y0, y1]` whose depth goes from `z0` (left) to
    /// `z1` (right).
    pub fn quad(m: &mut Mesh, [x0, y0, x1, y1]: [f32; 4], z0: f32, z1: f32) {
        let b = m.positions.len() as u32;
        m.positions.extend([
            Vec3::new(x0, y0, z0),
            Vec3::new(x1, y0, z1),
            Vec3::new(x1, y1, z1),
            Vec3::new(x0, y1, z0),
        ]);
        m.indices.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
    }

    /// Overlapping quads of several depths and slopes, two of them coplanar (equal depths,
    /// different primitives), some pixels uncovered, depth complexity up to 6.
    pub fn layers() -> Mesh {
        let mut m = Mesh::default();
        quad(&mut m, [-0.9, -0.9, 0.5, 0.6], 0.2, 0.2);
        quad(&mut m, [-0.5, -0.7, 0.9, 0.9], -0.6, 0.4);
        quad(&mut m, [-0.8, -0.2, 0.3, 0.8], 0.5, -0.5);
        quad(&mut m, [-0.8, -0.2, 0.3, 0.8], 0.5, -0.5); // coplanar with the previous one
        quad(&mut m, [-0.3, -0.95, 0.7, 0.1], 0.0, 0.0);
        quad(&mut m, [-1.0, -1.0, 1.0, 1.0], 0.9, 0.7);
        quad(&mut m, [0.6, 0.6, 0.95, 0.95], -0.2, -0.1);
        m
    }

    /// `count` full-screen quads of distinct depths: every pixel holds `count` fragments.
    pub fn stack(count: usize) -> Mesh {
        let mut m = Mesh::default();
        for i in 0..count {
            let z = -0.8 + 1.6 * i as f32 / count as f32;
            quad(&mut m, [-1.0, -1.0, 1.0, 1.0], z, z + 0.05);
        }
        m
    }

    pub fn frame(mesh: &Mesh, width: u32, height: u32) -> Frame<'_> {
        Frame {
            mesh,
            view_proj: Mat4::IDENTITY,
            width,
            height,
        }
    }

    /// Ordered, parallel, and scheduled under several policies and seeds.
    pub fn executors() -> Vec<ExecConfig> {
        let mut v = vec![
            ExecConfig::ordered(),
            ExecConfig::parallel(2),
            ExecConfig::parallel(4),
        ];
        for seed in 0..3 {
            v.push(ExecConfig::scheduled(Policy::Random, seed));
        }
        v.push(ExecConfig::scheduled(Policy::Pct { depth: 3 }, 7));
        v.push(ExecConfig::scheduled(Policy::Warp { lanes: 8 }, 1));
        v.push(ExecConfig::scheduled(Policy::Reverse, 0));
        v.push(ExecConfig::scheduled(Policy::FarFirst, 0));
        v
    }

    /// Runs `algo` and asserts what a hazard-free A-buffer owes: EPR 0 against truth, every
    /// check passing, nothing dropped, every fragment captured.
    pub fn assert_exact(
        algo: &dyn Algorithm,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> AlgoResult {
        let info = algo.info();
        let r = algo.run(frame, params, exec).expect("runs");
        let truth = Truth::capture(frame, 1).expect("truth");
        let m = oracle::compare(&info, &r, &truth, params);
        let what = format!("{} under {:?}", info.name, exec.mode);
        for c in &r.checks {
            assert!(c.passed, "{what}: check `{}` failed: {}", c.name, c.detail);
        }
        assert_eq!(
            m.epr, 0.0,
            "{what}: EPR {} (first error at {:?})",
            m.epr, m.first_error
        );
        assert_eq!(m.captured, m.generated, "{what}");
        assert_eq!(r.dropped, 0, "{what}");
        assert!(m.generated > 0, "{what}: empty scene");
        r
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;

    #[test]
    fn dfb_is_exact_under_every_executor() {
        let mesh = layers();
        let f = frame(&mesh, 24, 20);
        for exec in executors() {
            let r = assert_exact(&Dfb, &f, &Params::default(), &exec);
            assert_eq!(
                r.report.hazards.total(),
                0,
                "{:?}",
                r.report.hazard_list.first()
            );
        }
    }

    #[test]
    fn dfb_shell_sorts_deep_pixels() {
        // 20 fragments per pixel: the resolve takes the shell-sort branch.
        let mesh = stack(20);
        let f = frame(&mesh, 6, 5);
        for exec in [
            ExecConfig::ordered(),
            ExecConfig::parallel(3),
            ExecConfig::scheduled(fragrace_emu::Policy::Random, 3),
        ] {
            assert_exact(&Dfb, &f, &Params::default(), &exec);
        }
    }

    #[test]
    fn ranges_check_finds_overlaps_and_gaps() {
        assert!(ranges_check(&[(0, 2), (2, 3), (5, 1)], 6).passed);
        assert!(ranges_check(&[(5, 1), (0, 2), (2, 3), (9, 0)], 6).passed);
        assert!(!ranges_check(&[(0, 2), (1, 3)], 4).passed);
        assert!(!ranges_check(&[(0, 2), (3, 3)], 6).passed);
        assert!(!ranges_check(&[(0, 2)], 3).passed);
    }
}
