//! The first kernels: depth complexity (`count`, and `count-plain`, the minimal racy
//! kernel), the nearest surface (`opaque`), and `truth`, the exact A-buffer every other
//! algorithm is checked against.

use fragrace_emu::{
    Buf, CompareFunc, DepthState, ExecConfig, Format, Fragment, FragmentKernel, KernelInfo,
    SampleCount, TargetState,
};

use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Capture, CapturedFrag, Check, Frame,
    HazardClass, Params,
};
use crate::common::{self, capture_state, framebuffer, geometry_pass, pixels, sort_fragments};

/// Per-pixel fragment count with an atomic add (depth complexity): the kernel of `count` and
/// `truth`, and the count pass of every algorithm that sizes or accounts by it (DFB and SB,
/// the exactly sized linked-list pool as the llvmpipe peer's `count` pass, SRAB's loss
/// accounting).
pub struct CountKernel {
    pub counts: Buf<u32>,
}

impl FragmentKernel for CountKernel {
    fn info(&self) -> KernelInfo {
        // Reads no depth or barycentrics: the draw skips their planes.
        KernelInfo::new("count")
            .without_interpolants()
            // Each fragment counts at its own pixel only.
            .with_own_pixel_array(self.counts, 1)
    }
    async fn shade(&self, f: impl Fragment) {
        f.atomic_add(self.counts, f.pixel_index(), 1).await;
    }
}

/// The same with a plain load and store: two fragments of one pixel in flight together
/// lose an update.
struct CountPlainKernel {
    counts: Buf<u32>,
}

impl FragmentKernel for CountPlainKernel {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("count-plain")
            .without_interpolants()
            .with_pixel_array(self.counts, 1)
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let c = f.load(self.counts, p).await;
        f.store(self.counts, p, c + 1).await;
    }
}

/// `count`: depth complexity per pixel via `atomicAdd` (the llvmpipe peer's `--algo count`).
pub struct Count;
/// `count-plain`: `count` with a plain read-modify-write (hazard-prone by design).
pub struct CountPlain;

/// The frame of `count` (`plain`: of `count-plain`): one geometry pass into a fresh
/// buffer of one counter per pixel. [`count_check`] completes it.
fn count_frame(frame: &Frame<'_>, exec: &ExecConfig, plain: bool) -> Result<AlgoResult, AlgoError> {
    let mut device = common::fresh(exec);
    let counts = device.buffer::<u32>("counts", pixels(frame) as u64)?;
    let mut fb = framebuffer(frame, SampleCount::X1, &[])?;
    let report = if plain {
        geometry_pass(
            &device,
            &mut fb,
            frame,
            &capture_state(),
            &CountPlainKernel { counts },
            exec,
        )?
    } else {
        geometry_pass(
            &device,
            &mut fb,
            frame,
            &capture_state(),
            &CountKernel { counts },
            exec,
        )?
    };
    let values = device.memory.take(counts)?;
    Ok(AlgoResult {
        counts: Some(values),
        storage_bytes: device.memory.bytes(),
        report,
        ..Default::default()
    })
}

/// The check of a `count` frame: the counts add up to the fragments generated (their sum
/// reads the whole buffer back: at 2048x2048, 16 MB). What is missing was lost
/// ([`AlgoResult::dropped`]).
fn count_check(r: &mut AlgoResult, exec: &ExecConfig) {
    let total = r
        .counts
        .as_deref()
        .map_or(0, |values| common::parallel_sum(values, exec.threads));
    let generated = r.report.stats.fragments_generated;
    r.dropped = generated.saturating_sub(total);
    r.checks.push(Check::new(
        "every fragment counted once",
        total == generated,
        format!("sum of counts {total}, fragments generated {generated}"),
    ));
}

impl Algorithm for Count {
    /// Neither k (it counts every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "count",
            family: "basic",
            summary: "depth complexity: atomic add of 1 per fragment into a per-pixel counter",
            source:
                "llvmpipe peer `--algo count`; depth complexity as in every seed's results section",
            passes: "1 geometry",
            memory: "4 bytes",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::Count,
        }
    }
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        _params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        count_frame(frame, exec, false)
    }
    fn self_check(&self, result: &mut AlgoResult, exec: &ExecConfig) {
        count_check(result, exec);
    }
}

impl Algorithm for CountPlain {
    /// Neither k (it counts every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "count-plain",
            family: "basic",
            summary: "depth complexity with a plain load and store: the minimal racy kernel (lost updates)",
            source: "lost updates (docs/hazards.md); the read-modify-write hazard of Bavoil et al.'s k-buffer in its simplest form",
            passes: "1 geometry",
            memory: "4 bytes",
            hazard: HazardClass::HazardProne,
            capacity: Capacity::Count,
        }
    }
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        _params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        count_frame(frame, exec, true)
    }
    fn self_check(&self, result: &mut AlgoResult, exec: &ExecConfig) {
        let first = result.checks.len();
        count_check(result, exec);
        // For a racy kernel, losing counts is the expected outcome, not a broken invariant:
        // keep the figure, but as information.
        for c in &mut result.checks[first..] {
            c.name = "counts lost to races (informational)".into();
            c.passed = true;
        }
    }
}

/// Nearest surface with simple shading, through the fixed-function depth test.
struct OpaqueKernel;

impl FragmentKernel for OpaqueKernel {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("opaque")
    }
    async fn shade(&self, f: impl Fragment) {
        let c = common::prim_rgb(f.primitive_id());
        // Headlight-style shading by depth keeps the silhouette readable without normals.
        let shade = 1.0 - 0.5 * f.depth();
        f.output(0, [c[0] * shade, c[1] * shade, c[2] * shade, 1.0]);
        f.output(1, [f.depth(), f32::from_bits(f.primitive_id()), 0.0, 0.0]);
    }
}

/// `opaque`: the nearest surface by the depth test (LESS, write on).
pub struct Opaque;

impl Algorithm for Opaque {
    /// Neither k (it keeps the nearest fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "opaque",
            family: "basic",
            summary: "nearest surface through the fixed-function depth test, simple shading",
            source: "the classic z-buffer; baseline of every seed",
            passes: "1 geometry",
            memory: "4 + 4 bytes (colour + depth)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::Nearest,
        }
    }
    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let device = common::fresh(exec);
        let mut fb = framebuffer(frame, SampleCount::X1, &[Format::RGBA8, Format::RG32F])?;
        let bg = params.background;
        fb.clear_color(
            0,
            [
                bg[0].to_bits(),
                bg[1].to_bits(),
                bg[2].to_bits(),
                0f32.to_bits(),
            ],
        );
        fb.clear_color(1, [1f32.to_bits(), u32::MAX, 0, 0]);
        let mut state = capture_state();
        state.fragment.depth = DepthState {
            test: true,
            func: CompareFunc::Less,
            write: true,
        };
        state.fragment.targets = vec![
            TargetState::new(Format::RGBA8),
            TargetState::new(Format::RG32F),
        ];
        let report = geometry_pass(&device, &mut fb, frame, &state, &OpaqueKernel, exec)?;
        let colors = fb.image(0);
        let ids = fb.image(1);
        let n = pixels(frame);
        let image: Vec<[f32; 4]> = (0..n)
            .map(|p| colors.texels[p].map(f32::from_bits))
            .collect();
        let lists = (0..n).map(|p| {
            let t = ids.texels[p];
            if t[1] == u32::MAX {
                vec![]
            } else {
                vec![CapturedFrag {
                    depth: f32::from_bits(t[0]),
                    prim: t[1],
                }]
            }
        });
        let capture = Capture::from_lists(frame.width, frame.height, lists);
        Ok(AlgoResult {
            capture: Some(capture),
            image: Some(image),
            storage_bytes: n as u64 * 12,
            report,
            ..Default::default()
        })
    }
}

/// Truth's store pass: every fragment to its pixel's next slot of a compact array.
struct TruthStore {
    offsets: Buf<u32>,
    fill: Buf<u32>,
    depth: Buf<f32>,
    prim: Buf<u32>,
}

impl FragmentKernel for TruthStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("truth-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        let base = f.load(self.offsets, p).await;
        let slot = base + f.atomic_add(self.fill, p, 1).await;
        f.store(self.depth, slot, f.depth()).await;
        f.store(self.prim, slot, f.primitive_id()).await;
    }
}

/// `truth`: the exact A-buffer. Counts fragments per pixel, allocates exactly, captures
/// every fragment, sorts each pixel by depth then primitive id. Always runs under the
/// `ordered` executor: it is the oracle, not a subject.
pub struct Truth;

impl Truth {
    /// Runs truth on a frame (ordered executor, `threads` for the rasterizer).
    pub fn capture(frame: &Frame<'_>, threads: usize) -> Result<AlgoResult, AlgoError> {
        let exec = ExecConfig {
            threads,
            ..ExecConfig::ordered()
        };
        let n = pixels(frame);
        let counted = count_frame(frame, &exec, false)?;
        let counts = counted.counts.clone().unwrap_or_default();
        let mut offsets = Vec::with_capacity(n + 1);
        let mut total = 0u32;
        for &c in &counts {
            offsets.push(total);
            total += c;
        }
        let mut device = common::fresh(&exec);
        let off_buf = device.buffer::<u32>("offsets", n as u64)?;
        device.memory.write(off_buf, 0, &offsets)?;
        offsets.push(total);
        let fill = device.buffer::<u32>("fill", n as u64)?;
        let depth = device.buffer::<f32>("depth", total as u64)?;
        let prim = device.buffer::<u32>("prim", total as u64)?;
        let mut fb = framebuffer(frame, SampleCount::X1, &[])?;
        let store = TruthStore {
            offsets: off_buf,
            fill,
            depth,
            prim,
        };
        let mut report = counted.report.clone();
        report.merge(&geometry_pass(
            &device,
            &mut fb,
            frame,
            &capture_state(),
            &store,
            &exec,
        )?);
        let depths = device.memory.read(depth)?;
        let prims = device.memory.read(prim)?;
        let mut frags: Vec<CapturedFrag> = depths
            .iter()
            .zip(&prims)
            .map(|(&depth, &prim)| CapturedFrag { depth, prim })
            .collect();
        for p in 0..n {
            sort_fragments(&mut frags[offsets[p] as usize..offsets[p + 1] as usize]);
        }
        let filled = device.memory.read(fill)?;
        let checks = vec![Check::new(
            "store pass fills exactly what the count pass counted",
            filled[..] == counts[..],
            format!("{} pixels", n),
        )];
        Ok(AlgoResult {
            capture: Some(Capture {
                width: frame.width,
                height: frame.height,
                offsets,
                frags,
            }),
            counts: Some(counts),
            storage_bytes: device.memory.bytes(),
            report,
            checks,
            ..Default::default()
        })
    }
}

impl Algorithm for Truth {
    /// Neither k (it keeps every fragment) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "truth",
            family: "basic",
            summary: "exact A-buffer: every fragment, sorted by depth then primitive id (always ordered)",
            source: "the ground truth; the A-buffer of Carpenter 1984 as a count-scan-store (DFB, z-thickness paper)",
            passes: "2 geometry",
            memory: "8 + 8 n bytes",
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
        let mut r = Truth::capture(frame, exec.threads)?;
        if let Some(c) = &r.capture {
            r.image = Some(
                (0..c.pixels())
                    .map(|p| common::composite_frags(c.pixel(p), params.alpha, params.background))
                    .collect(),
            );
        }
        Ok(r)
    }
}
