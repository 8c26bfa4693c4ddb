//! Geometry culling for multi-pass peeling: the depth-fighting paper's section 3.3, "GPU
//! Optimizations for Multi-pass Rendering".
//!
//! "We propose to avoid rendering objects that are completely peeled from previous
//! iterations. ... Similarly to occlusion culling, we substitute a geometrically complex
//! object with its bounding box. If the bounding box of the object ends up entirely behind
//! the last captured contents of depth buffer, we may cull this object at the geometry level
//! ... This is easily realized by hardware occlusion queries. Due to the observation that
//! objects that are culled during a specific iteration, will be always culled in the
//! successive ones, we reuse the results of the occlusion queries from previous iterations.
//! ... we avoid the synchronization cost between the CPU and GPU required to obtain the
//! occlusion query result, by using conditional rendering. Note that conditional rendering
//! can also be used to automatically halt the iterative procedure of multi-pass rendering
//! methods." (3.3)
//!
//! [`Objects`] draws a scene pass object by object (each a range of the mesh's triangles,
//! [`Frame::objects`], drawn with `Draw::part`, so primitive ids stay the mesh's). With
//! culling on, at the end of every iteration each object not culled yet gets one occlusion
//! query: its bounding box (12 triangles, enlarged by a thousandth of its diagonal so that
//! rasterization and depth rounding stay conservative), drawn with the depth test
//! `GREATER_EQUAL` against the depth buffer holding the layer just peeled, no depth or colour
//! writes. No sample passes exactly when, in every pixel where the layer exists, the whole box
//! lies in front of it: then every fragment of the object is in front of the layer, and every
//! later pass of a front-to-back peeler (which discards what lies at or in front of its
//! previous layer) would discard it. Pixels where the layer is empty hold the cleared depth
//! `+inf`, which nothing passes: nothing is left to peel there. The object's later draws carry
//! the query as their condition (`PassState::condition`, conditional rendering): a query that
//! passed nothing skips them, and a culled object is never queried again. When every object
//! is culled, the next pass draws nothing, its own occlusion query is zero and the peel loop
//! ends: conditional rendering halts it.
//!
//! The peelers that keep their layer in a colour target rather than in the depth buffer
//! (`f2b-2p`, the dual peelers) query against that image instead ([`Remaining`]): the box is
//! drawn with no depth test, and its query kernel discards the samples the layer's test
//! would fail, so the samples that pass are those a depth test would have let through. A dual
//! peeler's pixels keep a range `[near, far]` still to peel from both ends; an object is done
//! when its box lies entirely in front of `near` or entirely behind `far`, which two queries
//! per object find (samples at or behind `near`, samples at or in front of `far`): the object
//! is culled when either passes nothing. (This is conservative: an object whose box is in front
//! of the range in some pixels and behind it in others is not culled. A GPU combines the two
//! queries with two conditional draws, or reads them back; the emulator's condition is their
//! minimum.)
//!
//! Culling changes no fragment the peelers keep (`GREATER_EQUAL` keeps objects with
//! fragments at the layer itself, which F2B meets again to count its coplanar losses): the
//! output is the same with and without it (`tests/geometry_culling.rs`). Queries are not
//! counted in `geometry_passes` (a scene pass drawn object by object is one geometry pass);
//! [`ObjectCulling`] reports objects drawn and queries issued per iteration.

use std::ops::Range;

use fragrace_emu::{
    CompareFunc, DepthState, Device, Draw, ExecConfig, Fragment, FragmentKernel, Framebuffer,
    Image, KernelInfo, Mesh, OcclusionQuery, PassReport, PassState, SampleCount,
};
use glam::Vec3;

use crate::algo::{AlgoError, Frame, Params};
use crate::common::capture_state;

/// Whether the multi-pass peelers cull completely peeled objects (`--geometry-culling`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GeometryCulling {
    /// Every pass draws the whole mesh at once.
    #[default]
    Off,
    /// Per-object draws, bounding-box occlusion queries and conditional rendering.
    Queries,
}

impl GeometryCulling {
    pub fn is_off(&self) -> bool {
        *self == GeometryCulling::Off
    }
}

/// One iteration of a culled peel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct CullIteration {
    /// Objects drawn by the iteration's first pass (the others were skipped by their
    /// condition).
    pub objects_drawn: u32,
    /// Objects queried at its end (those not culled yet): one occlusion query each, two for
    /// the dual peelers (see [`Remaining::Range`]).
    pub queries: u32,
}

/// What geometry culling did in a run.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ObjectCulling {
    pub objects: u32,
    pub iterations: Vec<CullIteration>,
}

/// The occlusion query's kernel: nothing to shade, the depth test counts.
struct Query;

impl FragmentKernel for Query {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("cull-query").without_interpolants()
    }
    async fn shade(&self, _f: impl Fragment) {}
}

/// The occlusion query of a layer kept in an image: a box sample passes iff `passes(z, texel)`.
struct ImageQuery<'i, F> {
    image: &'i Image,
    passes: F,
}

impl<F: Fn(f32, [u32; 4]) -> bool + Sync> FragmentKernel for ImageQuery<'_, F> {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("cull-query").with_discard()
    }
    async fn shade(&self, f: impl Fragment) {
        let texel = f.texel(self.image, f.x(), f.y(), 0);
        if !(self.passes)(f.depth(), texel) {
            f.discard();
        }
    }
}

/// What is left to peel, which an iteration's occlusion queries test each object's box
/// against ([`Objects::end_iteration`]).
pub(super) enum Remaining<'i> {
    /// The depth buffer of the peel's framebuffer holds the layer just peeled: a box sample
    /// passes at or behind it (`GREATER_EQUAL`).
    DepthBuffer(&'i mut Framebuffer),
    /// A front-to-back layer kept in an image: a box sample passes at or behind
    /// `depth(texel)` (`+inf` where nothing is left).
    Front {
        image: &'i Image,
        depth: fn([u32; 4]) -> f32,
    },
    /// A dual peeler's range kept in an image: `range(texel) = (near, far)`, what is left
    /// to peel from both ends (`near > far` where nothing is left).
    Range {
        image: &'i Image,
        range: fn([u32; 4]) -> (f32, f32),
    },
}

/// A query kernel of any type, drawn through one call (the queries of one object differ in
/// kernel type).
trait QueryKernel {
    fn draw(
        &self,
        device: &Device,
        fb: &mut Framebuffer,
        draw: &Draw<'_>,
        state: &PassState,
        exec: &ExecConfig,
    ) -> Result<PassReport, AlgoError>;
}

impl<K: FragmentKernel> QueryKernel for K {
    fn draw(
        &self,
        device: &Device,
        fb: &mut Framebuffer,
        draw: &Draw<'_>,
        state: &PassState,
        exec: &ExecConfig,
    ) -> Result<PassReport, AlgoError> {
        Ok(device.draw(fb, draw, state, self, exec)?)
    }
}

/// The 12 triangles of the box `[lo, hi]`.
fn box_mesh(lo: Vec3, hi: Vec3) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..8u32 {
        m.positions.push(Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        ));
    }
    // Two triangles per face; no face culling in the query pass, so winding is free.
    for [a, b, c, d] in [
        [0, 1, 3, 2],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 3, 7, 5],
    ] {
        m.indices.push([a, b, c]);
        m.indices.push([a, c, d]);
    }
    m
}

/// The bounding box of `triangles` of `mesh`, enlarged by a thousandth of its diagonal (and
/// a tiny absolute margin for flat objects).
fn bounding_box(mesh: &Mesh, triangles: &Range<u32>) -> Option<Mesh> {
    let tris = &mesh.indices[triangles.start as usize..triangles.end as usize];
    let mut it = tris.iter().flatten().map(|&i| mesh.positions[i as usize]);
    let first = it.next()?;
    let (lo, hi) = it.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
    let margin = (hi - lo).length() * 1e-3 + 1e-5;
    Some(box_mesh(lo - Vec3::splat(margin), hi + Vec3::splat(margin)))
}

/// A scene's objects, drawn one by one and culled by occlusion queries when asked to; or,
/// with culling off, the whole mesh in one draw.
pub(super) struct Objects<'m> {
    draw: Draw<'m>,
    on: bool,
    parts: Vec<Range<u32>>,
    /// Each object's bounding box (empty objects: `None`, never drawn).
    boxes: Vec<Option<Mesh>>,
    /// The last query of each object (`None`: not queried yet, drawn unconditionally).
    condition: Vec<Option<OcclusionQuery>>,
    query_state: PassState,
    /// The framebuffer of image queries (no target, no depth test), with culling on.
    query_fb: Option<Framebuffer>,
    /// Objects the current iteration's first pass drew.
    drawn: Option<u32>,
    summary: ObjectCulling,
}

impl<'m> Objects<'m> {
    pub fn new(frame: &Frame<'m>, params: &Params) -> Result<Objects<'m>, AlgoError> {
        let draw = Draw::new(frame.mesh, frame.view_proj);
        let on = params.geometry_culling == GeometryCulling::Queries;
        let n = frame.mesh.indices.len() as u32;
        let parts: Vec<Range<u32>> = if frame.objects.is_empty() {
            // One object: every triangle.
            std::iter::once(0..n).collect()
        } else {
            frame.objects.to_vec()
        };
        let mut next = 0;
        for r in &parts {
            if r.start != next || r.end < r.start || r.end > n {
                return Err(AlgoError::Invalid(format!(
                    "objects must be consecutive ranges covering the mesh's {n} triangles; got {r:?} after \
                     triangle {next}"
                )));
            }
            next = r.end;
        }
        if next != n {
            return Err(AlgoError::Invalid(format!(
                "the objects cover {next} of the mesh's {n} triangles"
            )));
        }
        let boxes = if on {
            parts.iter().map(|r| bounding_box(frame.mesh, r)).collect()
        } else {
            Vec::new()
        };
        let mut query_state = capture_state();
        query_state.fragment.depth = DepthState {
            test: true,
            func: CompareFunc::GreaterEqual,
            write: false,
        };
        Ok(Objects {
            draw,
            on,
            condition: vec![None; parts.len()],
            summary: ObjectCulling {
                objects: parts.len() as u32,
                iterations: Vec::new(),
            },
            parts,
            boxes,
            query_state,
            query_fb: if on {
                Some(crate::common::framebuffer(frame, SampleCount::X1, &[])?)
            } else {
                None
            },
            drawn: None,
        })
    }

    /// One geometry pass over the scene: the whole mesh, or (culling on) each object under
    /// its condition. The report is one geometry pass, `skipped` when every object was.
    pub fn draw<K: FragmentKernel>(
        &mut self,
        device: &Device,
        fb: &mut Framebuffer,
        state: &PassState,
        kernel: &K,
        exec: &ExecConfig,
    ) -> Result<PassReport, AlgoError> {
        if !self.on {
            return Ok(device.draw(fb, &self.draw, state, kernel, exec)?);
        }
        let mut total = PassReport::default();
        let mut drawn = 0u32;
        for (r, condition) in self.parts.iter().zip(&self.condition) {
            let st = PassState {
                condition: *condition,
                ..state.clone()
            };
            let pass = device.draw(fb, &self.draw.part(r.clone()), &st, kernel, exec)?;
            drawn += u32::from(!pass.skipped);
            total.merge(&pass);
        }
        total.stats.geometry_passes = 1;
        total.skipped = drawn == 0;
        self.drawn.get_or_insert(drawn);
        Ok(total)
    }

    /// The end of an iteration: with culling on, an occlusion query of each object not
    /// culled yet against what is left to peel (`remaining`: a depth buffer, or an image); their reports go into `report` without counting as geometry passes.
    pub fn end_iteration(
        &mut self,
        device: &Device,
        mut remaining: Remaining<'_>,
        exec: &ExecConfig,
        report: &mut PassReport,
    ) -> Result<(), AlgoError> {
        if !self.on {
            return Ok(());
        }
        let mut queries = 0;
        let view_proj = self.draw.view_proj;
        let no_depth = crate::common::capture_state();
        for (b, condition) in self.boxes.iter().zip(&mut self.condition) {
            if condition.is_some_and(|q| q.samples_passed == 0) {
                continue;
            }
            let Some(mesh) = b else {
                *condition = Some(OcclusionQuery { samples_passed: 0 });
                continue;
            };
            let draw = Draw::new(mesh, view_proj);
            let mut query = |fb: &mut Framebuffer, state: &PassState, kernel: &dyn QueryKernel| {
                let mut pass = kernel.draw(device, fb, &draw, state, exec)?;
                pass.stats.geometry_passes = 0;
                // Its fragments are the box's, not the scene's.
                pass.stats.fragments_generated = 0;
                report.merge(&pass);
                Ok::<_, AlgoError>(pass.query())
            };
            let q = match &mut remaining {
                Remaining::DepthBuffer(fb) => query(fb, &self.query_state, &Query)?,
                Remaining::Front { image, depth } => {
                    let qfb = self.query_fb.as_mut().expect("made with culling on");
                    let kernel = ImageQuery {
                        image,
                        passes: |z: f32, t: [u32; 4]| z >= depth(t),
                    };
                    query(qfb, &no_depth, &kernel)?
                }
                Remaining::Range { image, range } => {
                    let qfb = self.query_fb.as_mut().expect("made with culling on");
                    let behind_near = ImageQuery {
                        image,
                        passes: |z: f32, t: [u32; 4]| z >= range(t).0,
                    };
                    let before_far = ImageQuery {
                        image,
                        passes: |z: f32, t: [u32; 4]| z <= range(t).1,
                    };
                    let a = query(qfb, &no_depth, &behind_near)?;
                    let b = query(qfb, &no_depth, &before_far)?;
                    OcclusionQuery {
                        samples_passed: a.samples_passed.min(b.samples_passed),
                    }
                }
            };
            queries += 1;
            *condition = Some(q);
        }
        self.summary.iterations.push(CullIteration {
            objects_drawn: self.drawn.take().unwrap_or(0),
            queries,
        });
        Ok(())
    }

    /// The end of a dual peeler's iteration: the queries against its range image (RG32F
    /// `(-near, far)`, `-inf` where nothing is left, [`super::dual::dual_range`]), issued
    /// only while some pixel has a range left (after the last range pass, none).
    pub fn end_dual_iteration(
        &mut self,
        device: &Device,
        range: &Image,
        exec: &ExecConfig,
        report: &mut PassReport,
    ) -> Result<(), AlgoError> {
        if range
            .texels
            .iter()
            .all(|t| f32::from_bits(t[1]) == f32::NEG_INFINITY)
        {
            return Ok(());
        }
        let remaining = Remaining::Range {
            image: range,
            range: super::dual::dual_range,
        };
        self.end_iteration(device, remaining, exec, report)
    }

    /// What culling did (`None` when it was off), the last pass (which found nothing left,
    /// or ended the run at `k`) included.
    pub fn summary(&mut self) -> Option<ObjectCulling> {
        if let Some(drawn) = self.drawn.take() {
            self.summary.iterations.push(CullIteration {
                objects_drawn: drawn,
                queries: 0,
            });
        }
        self.on.then(|| self.summary.clone())
    }
}
