//! The stencil-routed A-buffer (SRAB; Myers & Bavoil, "Stencil routed A-buffer", SIGGRAPH
//! 2007 sketch, and the NVIDIA "Stencil Routed K-Buffer" SDK whitepaper, 2007; \[18\] in the
//! depth-fighting seed, section 2 and Table 1; \[BMO08\] in the occupancy-culling seed): up to
//! 8 fragments per pixel captured in one geometry pass by fixed-function hardware alone,
//! with no read-modify-write of shared memory.
//!
//! The 8 samples of an MSAA framebuffer are used as 8 slots. Their stencil values are set
//! to distinct values (sample `s` to `s + 2`, by 8 full-screen passes each restricted to one
//! sample by the sample mask). The capture draw then tests stencil `EQUAL 2` and decrements
//! on pass and on fail: the first fragment of a pixel passes on sample 0 only and writes its
//! depth and primitive id there, every sample's counter drops by one, so the next fragment
//! passes on sample 1, and so on. Fragments are routed in rasterization (API) order, so SRAB
//! keeps the **first** 8 fragments, not the nearest: it is an A-buffer of capacity 8
//! (`Capacity::All`), exact on pixels with at most 8 fragments and short on deeper ones.
//! A full-screen resolve reads the 8 samples, sorts and composites them (the paper sorts
//! with a bitonic network; any sort gives the same order here).
//!
//! **Lost fragments are counted exactly**, against the ground truth's fragments: a count
//! pass with the truth's single-sample rasterization gives each pixel's fragments `n`, and
//! the loss is `n` minus the fragments stored. (The whitepaper detects overflow with an
//! occlusion query on a full-screen pass; an exact figure needs a count.) The count pass
//! and a per-pixel counter of routed fragments in the capture kernel are instrumentation,
//! not part of the paper's algorithm.
//!
//! **The 8-bit stencil wrap.** Routing must decrement with saturation (`DecrClamp`, GL's
//! `DECR`, D3D's `DECR_SAT`): a sample's counter then passes 2 exactly once and settles at 0.
//! With a wrapping decrement (`DECR_WRAP`) the counter of sample `s` comes back to 2 after
//! 256 more fragments, and fragment `257 + s` silently overwrites sample `s`. The final
//! stencil of every sample is checked against `max(s + 2 - routed, 0)`, and the stored
//! fragments against API order, which catches the wrap (see the tests).
//!
//! **MSAA coverage.** Routing needs every fragment to cover all 8 samples: the paper turns
//! multisampling *off* while rendering into the MSAA target
//! (`D3D10_RASTERIZER_DESC::MultisampleEnable = FALSE`: pixel-centre coverage replicated to
//! every sample), which is why the depth-fighting seed calls SRAB incompatible with MSAA.
//! The capture sets `RasterState::multisample = false`, so every fragment covers all 8
//! samples. Should a fragment ever cover only some samples (multisampling on), it would
//! decrement only those counters and desynchronise the routing, so the capture kernel
//! still discards partially covering fragments before the (late) stencil test and counts
//! them: with multisampling off none is, and only the fragments beyond 8 are lost.
//!
//! **Occupancy culling** (`--occupancy D`; the occupancy-culling seed, Figure 1 right: "the
//! noticeable image quality improvement ... when fragment culling is enabled in the
//! stencil-routed k-buffer"). The stage of [`crate::occupancy`] finds each pixel's bound on
//! the depth of its k-th nearest fragment (`k <= 8`), and the capture discards fragments
//! beyond it, so the 8 samples go to fragments within the bound: the first 8 of them in API
//! order, which include the k nearest (Lemma 2.1). The test runs in the capture kernel, not
//! as an early depth test ([`crate::occupancy::CullTest::Shader`], the paper's shader-based
//! culling): in the fixed-function order the stencil test comes before the depth test, so a
//! fragment failing an early depth test would still decrement the routing counters of the
//! samples whose stencil test it fails, and two samples would end up routing the same
//! fragment. A fragment discarded by its shader before the late stencil test touches no
//! counter. Culled fragments are therefore still shaded; what culling buys SRAB is quality,
//! not speed (the paper: SRAB "is significantly lessened from the additional geometry pass").

use fragrace_emu::{
    Buf, CompareFunc, Coverage, ExecConfig, Format, Fragment, FragmentKernel, FragmentState, Framebuffer,
    Image, KernelInfo, PassState, RasterState, SampleCount, StencilFace, StencilOp, StencilState,
    TargetState,
};

use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, Capture, CapturedFrag, Check, Deferred,
    Frame, HazardClass, Params,
};
use crate::basic::CountKernel;
use crate::common::{
    self, capture_state, framebuffer, geometry_pass, pixels, sort_fragments, EMPTY,
};
use crate::occupancy::Culling;
use crate::resolve::{self, Composite};

/// Slots per pixel: the samples of the MSAA framebuffer.
const SAMPLES: usize = 8;
/// Every sample covered.
const FULL: u8 = 0xff;
/// Stencil value that routes a fragment into a sample; sample `s` starts at `ROUTE + s`.
const ROUTE: u8 = 2;

/// `srab`: the stencil-routed A-buffer, 8 samples.
pub struct Srab;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    vec![Box::new(Srab)]
}

/// How the capture draw decrements the routing counters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Routing {
    /// Saturating decrement (the paper's; never wraps).
    Saturate,
    /// Wrapping decrement: the 8-bit wrap hazard (tests only).
    #[cfg_attr(not(test), allow(dead_code))]
    Wrap,
}

impl Routing {
    fn op(self) -> StencilOp {
        match self {
            Routing::Saturate => StencilOp::DecrClamp,
            Routing::Wrap => StencilOp::DecrWrap,
        }
    }
    /// The stencil of a sample that started at `init` after `routed` fragments went by.
    fn predict(self, init: u8, routed: u32) -> u8 {
        match self {
            Routing::Saturate => (init as u32).saturating_sub(routed) as u8,
            Routing::Wrap => (init as u32).wrapping_sub(routed) as u8,
        }
    }
}

/// Stencil initialisation: a full-screen pass that shades nothing (the fixed-function
/// stencil write under the sample mask does the work).
struct StencilInit;

impl FragmentKernel for StencilInit {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("srab-stencil-init")
    }
    async fn shade(&self, _f: impl Fragment) {}
}

/// The capture: depth and primitive id to the one sample the stencil test lets through.
/// Partially covering fragments are discarded before the late stencil test (see the
/// module notes); the routed ones are counted per pixel (instrumentation).
struct Capture8 {
    routed: Buf<u32>,
    /// With occupancy culling: each pixel's bound, and a per-pixel count of the fragments
    /// discarded beyond it (instrumentation).
    cull: Option<ShaderCull>,
}

#[derive(Clone, Copy)]
struct ShaderCull {
    bound: Buf<f32>,
    culled: Buf<u32>,
}

impl FragmentKernel for Capture8 {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("srab-capture").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        if f.coverage() != FULL {
            f.discard();
            return;
        }
        if let Some(c) = self.cull {
            // The culling test, before the late stencil test: a fragment beyond the bound
            // leaves the routing counters alone (`depth <= bound` passes, as LEQUAL does).
            let bound = f.load(c.bound, f.pixel_index()).await;
            if !crate::occupancy::bits::passes(f.depth(), bound) {
                f.atomic_add(c.culled, f.pixel_index(), 1).await;
                f.discard();
                return;
            }
        }
        f.atomic_add(self.routed, f.pixel_index(), 1).await;
        f.output(0, [f.depth(), f32::from_bits(f.primitive_id()), 0.0, 0.0]);
    }
}

/// The resolve (full screen, single sample): read the 8 samples of the capture, sort,
/// composite front to back.
struct Resolve<'a> {
    image: &'a Image,
    composite: Composite,
}

impl FragmentKernel for Resolve<'_> {
    fn info(&self) -> KernelInfo {
        // At a pixel no geometry reached every sample is still the clear's EMPTY: the
        // composite of nothing.
        KernelInfo::new("srab-resolve").with_untouched_output(self.composite.background_bits())
    }
    async fn shade(&self, f: impl Fragment) {
        let mut frags = Vec::with_capacity(SAMPLES);
        for s in 0..SAMPLES as u32 {
            let t = f.texel(self.image, f.x(), f.y(), s);
            if t[1] != EMPTY {
                frags.push(CapturedFrag::from_bits(t[0], t[1]));
            }
        }
        sort_fragments(&mut frags);
        self.composite.output(&f, &frags);
    }
}

fn msaa_pass(fragment: FragmentState) -> PassState {
    PassState {
        raster: RasterState {
            samples: SampleCount::X8,
            // The paper's routing needs every fragment on all 8 samples (section comment).
            multisample: false,
            ..RasterState::default()
        },
        fragment,
        condition: None,
    }
}

fn stencil(face: StencilFace) -> StencilState {
    StencilState {
        enabled: true,
        front: face,
        back: face,
    }
}

/// Bytes of a framebuffer's colour targets plus a 32-bit depth-stencil per sample.
fn fb_bytes(fb: &Framebuffer) -> u64 {
    let per_sample: u64 = fb
        .formats
        .iter()
        .map(|f| 4 * f.channels() as u64)
        .sum::<u64>()
        + 4;
    fb.width as u64 * fb.height as u64 * fb.samples.count() as u64 * per_sample
}

impl Algorithm for Srab {
    /// Neither k (it keeps as many fragments as the samples (K = 8)) nor a spin cap.
    fn reads(&self, _: crate::Param) -> bool {
        false
    }

    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "srab",
            family: "k-buffer",
            summary: "stencil-routed A-buffer: the first 8 fragments per pixel (API order) routed \
                      to the 8 MSAA samples by stencil EQUAL 2 + saturating decrement; \
                      overflow counted exactly",
            source: "Myers & Bavoil, Stencil routed A-buffer, SIGGRAPH 2007 sketch + NVIDIA SDK \
                     whitepaper Stencil Routed K-Buffer (2007); depth-fighting seed [18] (sec. 2, \
                     Table 1), occupancy-culling seed [BMO08]",
            passes: "8 full-screen (stencil init) + 1 geometry (capture) + 1 full-screen \
                     (resolve); + 1 geometry count pass for the exact loss figure",
            memory: "4K+2 words in Table 1 of the depth-fighting paper (16K + 8 bytes, K = 8); \
                     here K samples x (RG32F depth+id + 32-bit depth-stencil) = 12K bytes",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::All,
        }
    }

    fn takes_occupancy(&self) -> bool {
        true
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        run(frame, params, exec, Routing::Saturate)
    }
}

fn run(
    frame: &Frame<'_>,
    params: &Params,
    exec: &ExecConfig,
    routing: Routing,
) -> Result<AlgoResult, AlgoError> {
    let n = pixels(frame);
    let (w, h) = (frame.width, frame.height);
    if params.occupancy.is_some() && !(1..=SAMPLES as u32).contains(&params.k) {
        return Err(AlgoError::Invalid(format!(
            "--k {}: srab holds {SAMPLES} fragments per pixel, so its occupancy culling keeps \
             the k nearest for k from 1 to {SAMPLES}",
            params.k
        )));
    }
    // The resolve skips the pixels no geometry reached (`with_untouched_output`).
    let mut device = common::fresh(exec).with_coverage(Coverage::Tracked);

    // 1. Count pass (instrumentation, loss accounting): the truth's fragments per pixel
    //    (single-sample rasterization).
    let counts = device.buffer::<u32>("srab-counts", n as u64)?;
    let mut count_fb = framebuffer(frame, SampleCount::X1, &[])?;
    let mut report = geometry_pass(
        &device,
        &mut count_fb,
        frame,
        &capture_state(),
        &CountKernel { counts },
        exec,
    )?;

    // 2. Stencil initialisation: sample s <- ROUTE + s, one sample-masked full-screen pass each.
    let mut fb = framebuffer(frame, SampleCount::X8, &[Format::RG32F])?;
    fb.clear_color(0, [1f32.to_bits(), EMPTY, 0, 0]);
    fb.clear_stencil(0);
    for s in 0..SAMPLES as u8 {
        let mut st = FragmentState::new();
        st.sample_mask = 1 << s;
        st.stencil = stencil(StencilFace {
            func: CompareFunc::Always,
            pass_op: StencilOp::Replace,
            reference: ROUTE + s,
            ..StencilFace::default()
        });
        report.merge(&device.fullscreen(&mut fb, &st, &StencilInit, exec)?);
    }

    // Occupancy culling (when asked): the stage's passes find each pixel's bound, which
    // the capture kernel tests itself (module notes).
    let culling = match params.occupancy {
        Some(_) => {
            let mut bound_fb = framebuffer(frame, SampleCount::X1, &[])?;
            Culling::prepare(&mut device, &mut bound_fb, frame, params, exec)?
        }
        None => None,
    };
    let cull = match &culling {
        Some(c) => {
            let bound = device.buffer::<f32>("srab-bound", n as u64)?;
            device.memory.write(bound, 0, c.bounds())?;
            let culled = device.buffer::<u32>("srab-culled", n as u64)?;
            Some(ShaderCull { bound, culled })
        }
        None => None,
    };

    // 3. Capture: stencil EQUAL ROUTE, decrement on pass and fail, no depth test.
    let routed = device.buffer::<u32>("srab-routed", n as u64)?;
    let mut cap_state = FragmentState::new();
    cap_state.targets = vec![TargetState::new(Format::RG32F)];
    cap_state.stencil = stencil(StencilFace {
        func: CompareFunc::Equal,
        fail_op: routing.op(),
        depth_fail_op: routing.op(),
        pass_op: routing.op(),
        reference: ROUTE,
        read_mask: 0xff,
        write_mask: 0xff,
    });
    let capture = geometry_pass(
        &device,
        &mut fb,
        frame,
        &msaa_pass(cap_state),
        &Capture8 { routed, cull },
        exec,
    )?;
    report.merge(&capture);
    let image = fb.image(0);
    let culled = match cull {
        Some(c) => device.memory.read(c.culled)?,
        None => vec![0; n],
    };
    let culled_total: u64 = culled.iter().map(|&c| c as u64).sum();
    let culling = culling.map(|mut c| {
        c.add_shader_peel(&capture, culled_total);
        let (stage, summary) = c.finish();
        report.merge(&stage);
        summary
    });

    // 4. Resolve.
    let mut out_fb = resolve::framebuffer(frame)?;
    let kernel = Resolve {
        image: &image,
        composite: Composite::of(params),
    };
    report.merge(&resolve::pass(&device, &mut out_fb, &kernel, exec)?);
    let storage_bytes = fb_bytes(&fb) + n as u64 * resolve::TARGET_BYTES + device.memory.bytes();
    let stats = capture.stats.clone();
    let culls = culling.is_some();
    // What the samples hold is read back and checked after the frame
    // ([`AlgoResult::deferred`]).
    let deferred = Deferred::new(move |r: &mut AlgoResult| {
        let frag_counts = device.memory.read(counts)?;
        let routed = device.memory.read(routed)?;
        let resolved = resolve::read_image(&out_fb);

        // Read back what the samples hold, and check the routing.
        let mut lists = Vec::with_capacity(n);
        let mut dropped = 0u64;
        let mut shallow_dropped = 0u64;
        // Fragments within the bound (all of them without culling) that found no sample.
        let mut lost_within = 0u64;
        let mut stencil_bad: Option<String> = None;
        let mut order_bad: Option<String> = None;
        let mut overcount: Option<String> = None;
        for (p, ((&nf, &r), &cp)) in frag_counts.iter().zip(&routed).zip(&culled).enumerate() {
            let (x, y) = (p as u32 % w, p as u32 / w);
            for s in 0..SAMPLES as u8 {
                let want = routing.predict(ROUTE + s, r);
                let got = fb.stencil(x, y, s as u32);
                if stencil_bad.is_none() && got != want {
                    stencil_bad = Some(format!(
                        "pixel ({x}, {y}) sample {s}: stencil {got}, expected {want} after {r} routed fragments"
                    ));
                }
            }
            let samples: Vec<Option<CapturedFrag>> = (0..SAMPLES)
                .map(|s| {
                    let t = image.texels[p * SAMPLES + s];
                    (t[1] != EMPTY).then(|| CapturedFrag::from_bits(t[0], t[1]))
                })
                .collect();
            let stored: Vec<CapturedFrag> = samples.iter().flatten().copied().collect();
            // Samples 0..min(routed, 8) hold the first routed fragments in API order (primitive
            // order within one draw), one each; the rest are empty.
            let m = (r as usize).min(SAMPLES);
            let prefix =
                samples[..m].iter().all(Option::is_some) && samples[m..].iter().all(Option::is_none);
            let ordered = stored.windows(2).all(|v| v[0].prim < v[1].prim);
            if order_bad.is_none() && !(prefix && ordered) {
                let prims: Vec<Option<u32>> = samples.iter().map(|s| s.map(|f| f.prim)).collect();
                order_bad = Some(format!(
                    "pixel ({x}, {y}), {r} routed fragments: samples hold {prims:?}"
                ));
            }
            let kept = stored.len() as u64;
            if kept > nf as u64 || r + cp > nf {
                if overcount.is_none() {
                    overcount = Some(format!(
                        "pixel ({x}, {y}): {kept} stored, {r} routed, {cp} culled, of {nf} fragments"
                    ));
                }
            } else {
                dropped += nf as u64 - kept;
                lost_within += (nf - cp) as u64 - kept;
                if nf as usize <= SAMPLES {
                    shallow_dropped += nf as u64 - kept;
                }
            }
            let mut list = stored;
            sort_fragments(&mut list);
            lists.push(list);
        }
        let counted: u64 = frag_counts.iter().map(|&c| c as u64).sum();
        let routed_total: u64 = routed.iter().map(|&c| c as u64).sum();
        let cs = &stats;
        let ok = |v: &Option<String>| v.is_none();
        let partial = cs.discarded - culled_total.min(cs.discarded);
        let mut checks = vec![
            Check::new(
                "capture: every fragment routed, culled or dropped for partial coverage, none faulted",
                routed_total + cs.discarded == cs.fragments_generated
                    && culled_total <= cs.discarded
                    && cs.shaded == cs.fragments_generated
                    && cs.faulted == 0,
                format!(
                    "routed {routed_total} + culled {culled_total} + partial {partial} of {} \
                     generated, {} shaded, {} faulted",
                    cs.fragments_generated, cs.shaded, cs.faulted
                ),
            ),
            Check::new(
                "stencil counters = initial - routed fragments, never wrapped",
                ok(&stencil_bad),
                stencil_bad.clone().unwrap_or_else(|| format!("{} samples", n * SAMPLES)),
            ),
            Check::new(
                "routing: first min(routed, 8) fragments in API order, one per sample",
                ok(&order_bad),
                order_bad.clone().unwrap_or_else(|| format!("{n} pixels")),
            ),
            Check::new(
                "stored and routed never exceed the pixel's fragments; losses counted",
                ok(&overcount),
                overcount.clone().unwrap_or_else(|| format!("dropped {dropped} of {counted}")),
            ),
            Check::new(
                "fragments dropped for partial MSAA coverage (informational)",
                true,
                format!(
                    "{partial} partially covering fragments dropped; {shallow_dropped} fragments lost on pixels \
                     with <= 8 fragments (none with multisample-off rasterization)"
                ),
            ),
        ];
        if culls {
            checks.push(Check::new(
                "fragments within the bound that found no sample (informational)",
                true,
                format!(
                    "{lost_within} of the {} fragments within their pixel's bound \
                     ({culled_total} culled beyond it)",
                    counted - culled_total
                ),
            ));
        }
        r.capture = Some(Capture::from_lists(w, h, lists));
        r.image = Some(resolved);
        r.checks.extend(checks);
        r.dropped = dropped;
        Ok(())
    });
    Ok(AlgoResult {
        report,
        storage_bytes,
        culling,
        deferred: Some(deferred),
        ..Default::default()
    })
}

#[cfg(test)]
mod tests {
    use fragrace_emu::{Mesh, Policy};
    use glam::Vec3;

    use super::*;
    use crate::basic::Truth;
    use crate::oracle;
    use crate::testing::frame_sized;

    /// A triangle covering the whole viewport (every sample of every pixel), NDC depth
    /// `z + tilt * x`.
    fn cover_all(mesh: &mut Mesh, z: f32, tilt: f32) {
        corner(mesh, -1.0, -1.0, z, tilt);
    }

    /// A right triangle with legs on `x = x0` and `y = y0` (NDC) and its hypotenuse off
    /// screen: covers the quadrant `x >= x0, y >= y0` of the viewport. With legs on pixel
    /// boundaries every pixel is covered on all samples or none.
    fn corner(mesh: &mut Mesh, x0: f32, y0: f32, z: f32, tilt: f32) {
        let b = mesh.positions.len() as u32;
        for (x, y) in [(x0, y0), (x0 + 8.0, y0), (x0, y0 + 8.0)] {
            mesh.positions
                .push(Vec3::new(x, y, z + tilt * x.clamp(-1.0, 1.0)));
        }
        mesh.indices.push([b, b + 1, b + 2]);
    }

    fn execs() -> Vec<ExecConfig> {
        let mut v = vec![ExecConfig::ordered(), ExecConfig::parallel(2)];
        for p in Policy::all() {
            for seed in [1, 9] {
                v.push(ExecConfig::scheduled(p.clone(), seed));
            }
        }
        v
    }

    fn assert_checks(r: &AlgoResult, what: &str) {
        for c in &r.checks {
            assert!(c.passed, "{what}: {} ({})", c.name, c.detail);
        }
    }

    #[test]
    fn exact_up_to_eight_fragments_and_losses_counted_beyond() {
        // 16x16 pixels; quadrant layers on pixel boundaries (NDC 0 = pixel 8, -0.5 = pixel 4)
        // give pixels with 5, 6, 7, 8, 9 and 11 fragments, in shuffled depth order.
        let mut mesh = Mesh::default();
        for (i, z) in [0.3, -0.6, 0.1, 0.8, -0.2].into_iter().enumerate() {
            cover_all(&mut mesh, z, 0.02 * i as f32);
        }
        corner(&mut mesh, 0.0, 0.0, -0.1, 0.0);
        corner(&mut mesh, -0.5, -0.5, 0.45, 0.05);
        corner(&mut mesh, -0.5, 0.0, -0.75, 0.0);
        corner(&mut mesh, 0.0, -0.5, 0.6, -0.05);
        corner(&mut mesh, 0.5, 0.5, 0.15, 0.0);
        corner(&mut mesh, 0.25, 0.25, 0.55, 0.0);
        corner(&mut mesh, 0.5, -1.0, 0.05, 0.0);
        let frame = frame_sized(&mesh, 16, 16);
        let truth = Truth::capture(&frame, 1).unwrap();
        let t = truth.capture.as_ref().unwrap();
        let params = Params::default();
        let expected_lost: u64 = (0..t.pixels())
            .map(|p| t.pixel(p).len().saturating_sub(8) as u64)
            .sum();
        let deep = (0..t.pixels()).filter(|&p| t.pixel(p).len() > 8).count() as u64;
        assert!(expected_lost > 0 && deep > 0 && deep < t.pixels() as u64);
        for exec in execs() {
            let r = Srab.run(&frame, &params, &exec).unwrap();
            assert_checks(&r, &format!("{:?}", exec.mode));
            assert_eq!(r.dropped, expected_lost, "{:?}", exec.mode);
            assert_eq!(r.report.hazards.total(), 0);
            let m = oracle::compare(&Srab.info(), &r, &truth, &params);
            // Errors exactly on the pixels with more than 8 fragments.
            for p in 0..t.pixels() {
                assert_eq!(
                    m.error_mask[p],
                    t.pixel(p).len() > 8,
                    "{:?} pixel {p}",
                    exec.mode
                );
            }
            assert_eq!(m.error_pixels, deep);
            // Pixels with <= 8 fragments: the resolved image is the exact composite.
            let img = r.image.as_ref().unwrap();
            for (p, got) in img.iter().enumerate() {
                let want = common::composite_frags(t.pixel(p), params.alpha, params.background);
                if t.pixel(p).len() <= 8 {
                    assert_eq!(*got, want, "pixel {p}");
                }
            }
        }
    }

    #[test]
    fn ten_layer_stack_keeps_the_first_eight_and_loses_two_per_pixel() {
        let mut mesh = Mesh::default();
        // Nearest layers last in API order: SRAB keeps the first 8, not the nearest 8.
        for i in 0..10 {
            cover_all(&mut mesh, 0.8 - 0.15 * i as f32, 0.01);
        }
        let frame = frame_sized(&mesh, 8, 8);
        let truth = Truth::capture(&frame, 1).unwrap();
        let params = Params::default();
        for exec in execs() {
            let r = Srab.run(&frame, &params, &exec).unwrap();
            assert_checks(&r, &format!("{:?}", exec.mode));
            assert_eq!(r.dropped, 64 * 2);
            let cap = r.capture.as_ref().unwrap();
            for p in 0..cap.pixels() {
                let mut prims: Vec<u32> = cap.pixel(p).iter().map(|f| f.prim).collect();
                prims.sort_unstable();
                assert_eq!(prims, (0..8).collect::<Vec<_>>());
            }
            let m = oracle::compare(&Srab.info(), &r, &truth, &params);
            assert_eq!(m.error_pixels, 64);
            assert_eq!(m.captured, 64 * 8);
        }
    }

    #[test]
    fn occupancy_culling_routes_the_eight_nearest_instead_of_the_first_eight() {
        use crate::occupancy::{CullTest, Occupancy};
        let mut mesh = Mesh::default();
        // Nearest layers last in API order: without culling SRAB keeps the 8 farthest.
        for i in 0..10 {
            cover_all(&mut mesh, 0.8 - 0.15 * i as f32, 0.01);
        }
        let frame = frame_sized(&mesh, 8, 8);
        let truth = Truth::capture(&frame, 1).unwrap();
        let plain = Params::default();
        let culled = Params {
            occupancy: Some(Occupancy {
                d: 1,
                range: Default::default(),
                fill: Default::default(),
            }),
            ..Params::default()
        };
        for exec in execs() {
            let r = Srab.run(&frame, &culled, &exec).unwrap();
            assert_checks(&r, &format!("{:?}", exec.mode));
            let c = r.culling.as_ref().expect("a culled run reports its stage");
            assert_eq!(c.test, CullTest::Shader);
            assert_eq!(c.culled_fragments, 64 * 2, "{:?}", exec.mode);
            assert_eq!(r.report.hazards.total(), 0);
            let cap = r.capture.as_ref().unwrap();
            for p in 0..cap.pixels() {
                let mut prims: Vec<u32> = cap.pixel(p).iter().map(|f| f.prim).collect();
                prims.sort_unstable();
                assert_eq!(prims, (2..10).collect::<Vec<_>>(), "{:?}", exec.mode);
            }
            let m = oracle::compare(&Srab.info(), &r, &truth, &culled);
            assert_eq!(m.lemma_2_1_violations, Some(0));
            assert_eq!(m.culled_truth, Some(64 * 2));
            // Still short of the A-buffer on every pixel (capacity 8 of 10), but the image
            // is nearer the truth than the unculled run's.
            assert_eq!(m.error_pixels, 64);
            let base = Srab.run(&frame, &plain, &exec).unwrap();
            let mb = oracle::compare(&Srab.info(), &base, &truth, &plain);
            let (ic, ib) = (m.image.unwrap(), mb.image.unwrap());
            assert!(ic.mse < ib.mse, "culled mse {} vs plain {}", ic.mse, ib.mse);
        }
        // More than 8 nearest cannot be routed into 8 samples.
        let too_many = Params { k: 9, ..culled };
        let Err(err) = Srab.run(&frame, &too_many, &ExecConfig::ordered()) else {
            panic!("k = 9 must be refused");
        };
        assert!(err.to_string().contains("--k 9"), "{err}");
    }

    /// The frame with `routing` and then its deferred checks (what `Algorithm::run` does).
    fn run_checked(frame: &Frame<'_>, params: &Params, exec: &ExecConfig, routing: Routing) -> AlgoResult {
        let mut r = run(frame, params, exec, routing).unwrap();
        if let Some(work) = r.deferred.take() {
            work.run(&mut r);
        }
        r
    }

    #[test]
    fn wrapping_decrement_overwrites_after_256_fragments_and_is_caught() {
        let mut mesh = Mesh::default();
        for i in 0..260 {
            cover_all(&mut mesh, -0.9 + 1.8 * (i as f32 / 260.0), 0.0);
        }
        let frame = frame_sized(&mesh, 4, 4);
        let params = Params::default();
        let exec = ExecConfig::ordered();
        let good = run_checked(&frame, &params, &exec, Routing::Saturate);
        assert_checks(&good, "saturating");
        assert_eq!(good.dropped, 16 * 252);
        let bad = run_checked(&frame, &params, &exec, Routing::Wrap);
        // Fragments 257..260 came back to samples 0..3 and overwrote fragments 1..4.
        let cap = bad.capture.as_ref().unwrap();
        let mut prims: Vec<u32> = cap.pixel(0).iter().map(|f| f.prim).collect();
        prims.sort_unstable();
        assert_eq!(prims, vec![4, 5, 6, 7, 256, 257, 258, 259]);
        let routing = bad
            .checks
            .iter()
            .find(|c| c.name.starts_with("routing"))
            .unwrap();
        assert!(
            !routing.passed,
            "the wrap must be caught: {}",
            routing.detail
        );
    }

    #[test]
    fn edge_pixels_are_routed_whole_with_multisampling_off() {
        // Quads with edges inside pixels (and their diagonals) would cover pixels partially
        // at 8 samples; with multisampling off each fragment covers all samples or none (by
        // its centre), so nothing is dropped and the result is exact (at most 4 layers).
        let mut mesh = Mesh::default();
        for (i, z) in [0.0f32, 0.4, -0.3].into_iter().enumerate() {
            let o = 0.13 * i as f32;
            let b = mesh.positions.len() as u32;
            mesh.positions.extend([
                Vec3::new(-0.7 + o, -0.7, z),
                Vec3::new(0.7, -0.7 + o, z),
                Vec3::new(0.7 - o, 0.7, z),
                Vec3::new(-0.7, 0.7 - o, z),
            ]);
            mesh.indices.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        }
        cover_all(&mut mesh, 0.2, 0.0);
        let frame = frame_sized(&mesh, 16, 16);
        let truth = Truth::capture(&frame, 1).unwrap();
        let t = truth.capture.as_ref().unwrap();
        let params = Params::default();
        for exec in execs() {
            let r = Srab.run(&frame, &params, &exec).unwrap();
            assert_checks(&r, &format!("{:?}", exec.mode));
            let info = r
                .checks
                .iter()
                .find(|c| c.name.contains("partial MSAA"))
                .unwrap();
            assert!(info.detail.starts_with("0 "), "{}", info.detail);
            let cap = r.capture.as_ref().unwrap();
            let m = oracle::compare(&Srab.info(), &r, &truth, &params);
            let mut lost = 0;
            for p in 0..t.pixels() {
                assert!(
                    cap.pixel(p).iter().all(|f| t.pixel(p).contains(f)),
                    "pixel {p}"
                );
                assert_eq!(
                    m.error_mask[p],
                    cap.pixel(p).len() < t.pixel(p).len(),
                    "pixel {p}"
                );
                lost += t.pixel(p).len() - cap.pixel(p).len();
            }
            assert_eq!(r.dropped, lost as u64);
            assert_eq!((r.dropped, m.error_pixels), (0, 0));
        }
    }
}
