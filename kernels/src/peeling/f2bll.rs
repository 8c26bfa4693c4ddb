//! `f2b-ll`: the depth-fighting paper's coplanarity-aware front-to-back peeling with
//! per-pixel linked lists (section 3.1.3, Algorithm 2 "F2B-LL Depth Peeling").
//!
//! "The idea is to store *all* fragments located at the extracted depth layer(s) using
//! linked-list structures. Coplanarity issues can be easily handled using this technique
//! without wasting any memory." Each iteration has two geometry passes:
//!
//! 1. a depth pass (the paper's "double speed" pass): depth test `LESS` with writes, the
//!    kernel discards fragments at or in front of the previous layer (read from the previous
//!    iteration's R32F target), so the depth buffer ends holding the next layer;
//! 2. a capture pass over the same depth buffer with the test `EQUAL` and writes off (early
//!    tests: the fragments of other layers never run the kernel, the paper's "early-culling
//!    optimizations"): every fragment at the layer is pushed onto its pixel's list, "where
//!    ← denotes an atomic memory operation": a global atomic counter allocates the node, an
//!    atomic exchange on the pixel's head publishes it (payload written before, the `next`
//!    link after, as the `ll` A-buffer does).
//!
//! One node pool serves every iteration (no fragment is captured twice, so the fragments of
//! the first depth pass bound it), and one list per pixel accumulates its layers; the host
//! walks the lists at the end and sorts each by (depth, primitive). "Despite the fact that
//! order of thread execution is not guaranteed, list sorting is not necessary since all
//! captured fragments are coplanar" (3.1.3): within a layer the list order is the race's;
//! sorting makes the capture's order the truth's.
//!
//! **Invariants (checked on every run).** The lists hold exactly the fragments the capture
//! passes let through (their occlusion queries), each once, with no link out of the pool and
//! no cycle; the pool never overflows (its size is an upper bound). Robust: EPR 0 and
//! `R_h = 1` under every executor (asserted by the differential harness).

use fragrace_emu::{
    Buf, CompareFunc, DepthState, Device, EarlyTests, ExecConfig, Format, Fragment, FragmentKernel,
    Framebuffer, Image, KernelInfo, PassReport, PassState, TargetState,
};

use super::culling::Objects;
use super::Peeled;
use crate::algo::{
    AlgoError, AlgoInfo, AlgoResult, Algorithm, Capacity, CapturedFrag, Check, Frame, HazardClass,
    Params,
};
use crate::common::{capture_state, sort_fragments, EMPTY};

/// Words per node: `[depth bits, primitive, next]`.
const NODE_WORDS: u32 = 3;

/// Pass 1: the next layer into the depth buffer and target 0.
struct DepthPass<'i> {
    /// The previous layer (R32F depth, `+inf` where the pixel is finished).
    prev: Option<&'i Image>,
}

impl FragmentKernel for DepthPass<'_> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-ll-depth").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let z = f.depth();
        if let Some(prev) = self.prev {
            if z <= f32::from_bits(f.texel(prev, f.x(), f.y(), 0)[0]) {
                f.discard();
                return;
            }
        }
        f.output(0, [z, 0.0, 0.0, 0.0]);
    }
}

/// The two passes of an F2B-LL or F2B-B iteration over one framebuffer: the depth pass
/// that leaves the next layer in the depth buffer, and the capture pass that runs a kernel on
/// the fragments at that layer (depth test `EQUAL`, early, no writes).
pub(super) struct LayerPasses<'m> {
    /// The scene, drawn whole or object by object (geometry culling).
    objects: Objects<'m>,
    fb: Framebuffer,
    depth_state: PassState,
    capture_state: PassState,
    /// The last layer (R32F depth), once a depth pass has run.
    prev: Option<Image>,
    /// Fragments a geometry pass generates (all of the scene's).
    pub generated: u64,
    /// A depth pass found nothing left behind the last layer.
    pub exhausted: bool,
}

impl<'m> LayerPasses<'m> {
    pub fn new(peeled: &Peeled<'_>, frame: &Frame<'m>) -> Result<LayerPasses<'m>, AlgoError> {
        let mut depth_state = capture_state();
        depth_state.fragment.depth = DepthState {
            test: true,
            func: CompareFunc::Less,
            write: true,
        };
        depth_state.fragment.targets = vec![TargetState::new(Format::R32F)];
        let mut capture = capture_state();
        capture.fragment.depth = DepthState {
            test: true,
            func: CompareFunc::Equal,
            write: false,
        };
        capture.fragment.early = EarlyTests::ForceEarly;
        Ok(LayerPasses {
            objects: Objects::new(frame, peeled.params)?,
            fb: peeled.framebuffer(&[Format::R32F])?,
            depth_state,
            capture_state: capture,
            prev: None,
            generated: 0,
            exhausted: false,
        })
    }

    /// The depth pass of the next layer; `None` when no fragment is left behind the last.
    pub fn next_layer(
        &mut self,
        device: &Device,
        exec: &ExecConfig,
        report: &mut PassReport,
    ) -> Result<Option<PassReport>, AlgoError> {
        self.fb.clear_depth(f32::INFINITY);
        self.fb.clear_color(0, [f32::INFINITY.to_bits(), 0, 0, 0]);
        let kernel = DepthPass {
            prev: self.prev.as_ref(),
        };
        let pass = self
            .objects
            .draw(device, &mut self.fb, &self.depth_state, &kernel, exec)?;
        report.merge(&pass);
        // The first pass draws every object (culling skips some later).
        self.generated = self.generated.max(pass.stats.fragments_generated);
        if pass.stats.samples_passed == 0 {
            self.exhausted = true;
            return Ok(None);
        }
        self.prev = Some(self.fb.image(0));
        Ok(Some(pass))
    }

    /// The layer the last depth pass found (R32F depth, `+inf` where none), once one ran.
    pub fn layer(&self) -> Option<&Image> {
        self.prev.as_ref()
    }

    /// Runs `kernel` on the fragments at the layer the last depth pass found.
    pub fn capture<K: FragmentKernel>(
        &mut self,
        device: &Device,
        kernel: &K,
        exec: &ExecConfig,
        report: &mut PassReport,
    ) -> Result<PassReport, AlgoError> {
        let pass = self
            .objects
            .draw(device, &mut self.fb, &self.capture_state, kernel, exec)?;
        report.merge(&pass);
        Ok(pass)
    }

    /// The end of an iteration: the occlusion queries of geometry culling, if on.
    pub fn end_iteration(
        &mut self,
        device: &Device,
        exec: &ExecConfig,
        report: &mut PassReport,
    ) -> Result<(), AlgoError> {
        self.objects
            .end_iteration(
                device,
                super::culling::Remaining::DepthBuffer(&mut self.fb),
                exec,
                report,
            )
    }

    /// What geometry culling did (`None` when it was off).
    pub fn culling(&mut self) -> Option<super::ObjectCulling> {
        self.objects.summary()
    }
}

/// The list buffers: heads (`EMPTY` = empty list), a pool of nodes of [`NODE_WORDS`] words,
/// and the allocation counters.
#[derive(Clone, Copy)]
pub(super) struct Lists {
    pub heads: Buf<u32>,
    pub nodes: Buf<u32>,
    /// `[allocated, dropped, ...]` (DUAL-LL adds the back lists' allocation).
    pub counters: Buf<u32>,
    pub capacity: u32,
}

/// What the host found walking the lists.
pub(super) struct Walked {
    pub stored: u64,
    /// Links to a node outside the pool.
    pub bad_links: u64,
    /// Nodes reached twice (a cycle, or two lists sharing a tail).
    pub revisits: u64,
}

impl Lists {
    /// `heads` empty lists, a pool of `capacity` nodes, `counters` counters.
    pub fn new(
        device: &mut Device,
        prefix: &str,
        heads: u64,
        capacity: u64,
        counters: u64,
    ) -> Result<Lists, AlgoError> {
        let capacity = capacity.max(1);
        if capacity * NODE_WORDS as u64 > fragrace_emu::memory::MAX_BUFFER_WORDS {
            return Err(AlgoError::Invalid(format!(
                "{prefix}: a pool of {capacity} nodes is larger than a buffer can hold"
            )));
        }
        let h = device.buffer::<u32>(&format!("{prefix}-heads"), heads)?;
        device.memory.fill(h, EMPTY)?;
        let nodes =
            device.buffer::<u32>(&format!("{prefix}-nodes"), capacity * NODE_WORDS as u64)?;
        device.memory.fill(nodes, EMPTY)?;
        Ok(Lists {
            heads: h,
            nodes,
            counters: device.buffer::<u32>(&format!("{prefix}-counters"), counters)?,
            capacity: capacity as u32,
        })
    }

    /// Walks every list on the host (bounded: a node is visited once), appending list `h`'s
    /// fragments to `out[h % out.len()]`, and sorts each pixel's fragments.
    pub fn walk(
        &self,
        device: &Device,
        out: &mut [Vec<CapturedFrag>],
    ) -> Result<Walked, AlgoError> {
        let heads = device.memory.read(self.heads)?;
        let nodes = device.memory.read(self.nodes)?;
        let mut w = Walked {
            stored: 0,
            bad_links: 0,
            revisits: 0,
        };
        let mut seen = vec![false; self.capacity as usize];
        let n = out.len().max(1);
        for (h, &head) in heads.iter().enumerate() {
            let list = &mut out[h % n];
            let mut cur = head;
            while cur != EMPTY {
                if cur >= self.capacity {
                    w.bad_links += 1;
                    break;
                }
                if std::mem::replace(&mut seen[cur as usize], true) {
                    w.revisits += 1;
                    break;
                }
                let at = (cur * NODE_WORDS) as usize;
                list.push(CapturedFrag::from_bits(nodes[at], nodes[at + 1]));
                w.stored += 1;
                cur = nodes[at + 2];
            }
        }
        for list in out.iter_mut() {
            sort_fragments(list);
        }
        Ok(w)
    }
}

/// Writes the fragment into `node` and pushes it onto list `head`: payload first, the atomic
/// exchange on the head publishes it, then the `next` link the exchange returned (as the
/// `ll` A-buffer does).
pub(super) async fn link(f: &impl Fragment, l: &Lists, head: u32, node: u32) {
    let at = node * NODE_WORDS;
    f.store_record(l.nodes, at, &[f.depth().to_bits(), f.primitive_id()])
        .await;
    let next = f.atomic_exchange(l.heads, head, node).await;
    f.store(l.nodes, at + 2, next).await;
}

/// Pass 2: every fragment at the layer (depth test `EQUAL`) onto its pixel's list.
struct CapturePass {
    lists: Lists,
}

impl FragmentKernel for CapturePass {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("f2b-ll-capture")
    }
    async fn shade(&self, f: impl Fragment) {
        let l = &self.lists;
        let node = f.atomic_add(l.counters, 0, 1).await;
        if node >= l.capacity {
            f.atomic_add(l.counters, 1, 1).await;
            return;
        }
        link(&f, l, f.pixel_index(), node).await;
    }
}

/// `f2b-ll`: see the module documentation.
pub struct F2bLl;

impl Algorithm for F2bLl {
    fn info(&self) -> AlgoInfo {
        AlgoInfo {
            name: "f2b-ll",
            family: "depth peeling",
            summary: "coplanarity-aware front-to-back peeling with linked lists: a depth pass finds the next layer, \
                      an EQUAL-tested pass pushes all of its (coplanar) fragments onto per-pixel lists",
            source: "depth-fighting paper, section 3.1.3 (F2B-LL, Algorithm 2) and Table 1",
            passes: "2 geometry per iteration (at most k), halted by occlusion queries",
            memory: "16 + 12 n bytes: depth buffer, R32F layer, the previous layer read-only, list head; depth, \
                     primitive and next per node, one pool for the whole scene (Table 1's 2C + 4 words, C the \
                     largest coplanar group, assume a pool reused per layer)",
            hazard: HazardClass::HazardFree,
            capacity: Capacity::KNearest,
        }
    }

    fn takes_geometry_culling(&self) -> bool {
        true
    }

    fn run_frame(
        &self,
        frame: &Frame<'_>,
        params: &Params,
        exec: &fragrace_emu::ExecConfig,
    ) -> Result<AlgoResult, AlgoError> {
        let mut peeled = Peeled::new(frame, params)?;
        let mut device = crate::common::fresh(exec);
        let mut layers = LayerPasses::new(&peeled, frame)?;
        let mut report = PassReport::default();
        let mut lists: Option<Lists> = None;
        let mut pushed = 0u64;
        while peeled.iterations < peeled.k {
            let Some(depth_pass) = layers.next_layer(&device, exec, &mut report)? else {
                break;
            };
            let l = match lists {
                Some(l) => l,
                None => {
                    // The first depth pass rasterized every fragment: a bound on the pool.
                    let capacity = depth_pass.stats.fragments_generated;
                    let pixels = peeled.lists.len() as u64;
                    *lists.insert(Lists::new(&mut device, "f2b-ll", pixels, capacity, 2)?)
                }
            };
            let captured = layers.capture(&device, &CapturePass { lists: l }, exec, &mut report)?;
            peeled.iterations += 1;
            pushed += captured.stats.samples_passed;
            layers.end_iteration(&device, exec, &mut report)?;
        }

        let mut checks = vec![super::conservation(
            layers.exhausted,
            pushed,
            layers.generated,
        )];
        if let Some(l) = lists {
            let counters = device.memory.read(l.counters)?;
            let Walked {
                stored,
                bad_links,
                revisits,
            } = l.walk(&device, &mut peeled.lists)?;
            checks.push(Check::new(
                "the lists hold each captured fragment once, in range, acyclic",
                bad_links == 0 && revisits == 0 && stored == pushed && u64::from(counters[0]) == pushed,
                format!(
                    "{stored} stored of {pushed} let through the EQUAL test ({} allocated); {bad_links} links out \
                     of the pool, {revisits} nodes reached twice",
                    counters[0]
                ),
            ));
            checks.push(Check::new(
                "the pool never overflows",
                counters[1] == 0,
                format!("{} fragments dropped", counters[1]),
            ));
        }
        let bytes = device.memory.bytes();
        let mut result = peeled.finish(report, checks, bytes, 12);
        result.geometry_culling = layers.culling();
        Ok(result)
    }
}


/// The algorithms of this file, for its family's registry line.
pub(super) fn algorithms() -> Vec<Box<dyn crate::algo::Algorithm>> {
    vec![Box::new(F2bLl)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::assert_exact_everywhere;

    #[test]
    fn exact_under_every_executor_with_coplanar_fragments() {
        assert_exact_everywhere(&F2bLl, &Params::default(), 1);
    }
}
