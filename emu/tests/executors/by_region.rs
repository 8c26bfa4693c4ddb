//! A geometry pass and a full-screen pass that reads by region, run together
//! (`Device::draw_then_fullscreen`, tile by tile on the direct executors): the same image,
//! lists and counts as the two passes one after the other, under every executor.

use fragrace_emu::{
    Buf, Coverage, Device, Draw, ExecConfig, ExecMode, Format, Fragment, FragmentKernel,
    FragmentState, Framebuffer, KernelInfo, PassReport, PassState, SampleCount, TargetState,
};
use glam::Vec3;

use super::common::*;

const EMPTY: u32 = u32::MAX;
const W: u32 = 37;
const H: u32 = 29;

/// Per-pixel linked lists: a node from one global counter, the fragment's primitive id in
/// it, linked in by exchanging the pixel's head.
struct Insert {
    heads: Buf<u32>,
    nodes: Buf<u32>,
    next: Buf<u32>,
}

impl FragmentKernel for Insert {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("insert").without_interpolants()
    }
    async fn shade(&self, f: impl Fragment) {
        let node = f.atomic_add(self.next, 0, 1).await;
        f.store(self.nodes, node * 2, f.primitive_id()).await;
        let old = f.atomic_exchange(self.heads, f.pixel_index(), node).await;
        f.store(self.nodes, node * 2 + 1, old).await;
    }
}

/// Walks its pixel's list: writes how many nodes and the sum of their primitive ids plus
/// one, and at an untouched pixel (an empty list) `empty`.
struct Walk {
    heads: Buf<u32>,
    nodes: Buf<u32>,
    by_region: bool,
    empty: [u32; 4],
}

impl FragmentKernel for Walk {
    fn info(&self) -> KernelInfo {
        let info = KernelInfo::new("walk").with_untouched_output(self.empty);
        if self.by_region {
            info.with_by_region_reads()
        } else {
            info
        }
    }
    async fn shade(&self, f: impl Fragment) {
        let mut cur = f.load(self.heads, f.pixel_index()).await;
        let (mut n, mut sum) = (0u32, 0u32);
        while cur != EMPTY {
            sum += f.load(self.nodes, cur * 2).await + 1;
            n += 1;
            cur = f.load(self.nodes, cur * 2 + 1).await;
        }
        f.output_u32(0, if n == 0 { self.empty } else { [n, sum, 0, 0] });
    }
}

/// Writes `value` at column 0 and discards elsewhere.
struct Column0 {
    value: [u32; 4],
}

impl FragmentKernel for Column0 {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("column-0")
    }
    async fn shade(&self, f: impl Fragment) {
        if f.x() == 0 {
            f.output_u32(0, self.value);
        } else {
            f.discard();
        }
    }
}

/// Overlapping triangles over part of the screen (blocks and tiles no fragment reaches).
fn mesh() -> fragrace_emu::Mesh {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for (i, (x, y, s)) in [
        (-0.8f32, -0.7f32, 0.9f32),
        (-0.5, -0.4, 0.8),
        (0.1, 0.0, 0.6),
    ]
    .into_iter()
    .enumerate()
    {
        let b = positions.len() as u32;
        let z = 0.2 + 0.1 * i as f32;
        positions.extend([
            Vec3::new(x, y, z),
            Vec3::new(x + s, y, z),
            Vec3::new(x, y + s, z),
        ]);
        indices.push([b, b + 1, b + 2]);
    }
    fragrace_emu::Mesh {
        positions,
        normals: None,
        indices,
    }
}

struct Outcome {
    image: Vec<[u32; 4]>,
    /// Each pixel's list, as (primitive id) sets: node indices may differ.
    lists: Vec<Vec<u32>>,
    geometry: PassReport,
    full: PassReport,
}

fn run(exec: &ExecConfig, together: bool, by_region: bool) -> Outcome {
    run_with(exec, together, by_region, [0; 4], None)
}

/// [`run`] with the walk's output at empty pixels, and a full-screen pass of [`Column0`]
/// writing `then` at column 0 after the two passes.
fn run_with(
    exec: &ExecConfig,
    together: bool,
    by_region: bool,
    empty: [u32; 4],
    then: Option<[u32; 4]>,
) -> Outcome {
    let mut dev = Device::new().with_coverage(Coverage::Tracked);
    let n = (W * H) as u64;
    let heads = dev.buffer::<u32>("heads", n).unwrap();
    let nodes = dev.buffer::<u32>("nodes", 2 * 4 * n).unwrap();
    let next = dev.buffer::<u32>("next", 1).unwrap();
    dev.memory.fill(heads, EMPTY).unwrap();
    let mut fb = Framebuffer::new(W, H, SampleCount::X1, 8, &[Format::RGBA32UI]).unwrap();
    let mesh = mesh();
    let draw = Draw::new(&mesh, glam::Mat4::IDENTITY);
    let state = PassState {
        raster: Default::default(),
        fragment: FragmentState::new(),
        condition: None,
    };
    let mut fs_state = FragmentState::new();
    fs_state.targets = vec![TargetState::new(Format::RGBA32UI)];
    let insert = Insert { heads, nodes, next };
    let walk = Walk {
        heads,
        nodes,
        by_region,
        empty,
    };
    let (geometry, full) = if together {
        dev.draw_then_fullscreen(&mut fb, &draw, &state, &insert, &fs_state, &walk, exec)
            .unwrap()
    } else {
        let g = dev.draw(&mut fb, &draw, &state, &insert, exec).unwrap();
        let f = dev.fullscreen(&mut fb, &fs_state, &walk, exec).unwrap();
        (g, f)
    };
    if let Some(value) = then {
        dev.fullscreen(&mut fb, &fs_state, &Column0 { value }, exec)
            .unwrap();
    }
    let h = dev.memory.read(heads).unwrap();
    let nd = dev.memory.read(nodes).unwrap();
    let lists = h
        .iter()
        .map(|&head| {
            let mut l = Vec::new();
            let mut cur = head;
            while cur != EMPTY {
                l.push(nd[cur as usize * 2]);
                cur = nd[cur as usize * 2 + 1];
            }
            l.sort_unstable();
            l
        })
        .collect();
    Outcome {
        image: fb.image(0).texels,
        lists,
        geometry,
        full,
    }
}

#[test]
fn by_region_passes_run_together_give_the_two_passes_results_under_every_executor() {
    let mut execs = all_execs();
    execs.extend(direct_execs());
    let truth = run(&ExecConfig::ordered(), false, false);
    let covered = truth.lists.iter().filter(|l| !l.is_empty()).count();
    assert!(covered > 0 && covered < (W * H) as usize / 2, "{covered}");
    assert!(truth.lists.iter().any(|l| l.len() > 1), "overlapping lists");
    assert!(truth.full.stats.skipped > 0, "untouched blocks skipped");
    for exec in &execs {
        for by_region in [false, true] {
            let r = run(exec, true, by_region);
            let what = format!("{:?}, by region {by_region}", exec.mode);
            assert_eq!(r.image, truth.image, "{what}");
            assert_eq!(r.lists, truth.lists, "{what}");
            let (g, f) = (&r.geometry.stats, &r.full.stats);
            assert_eq!(
                g.fragments_generated,
                truth.geometry.stats.fragments_generated
            );
            assert_eq!(g.shaded, truth.geometry.stats.shaded, "{what}");
            assert_eq!((g.geometry_passes, f.fullscreen_passes), (1, 1), "{what}");
            assert_eq!(f.shaded + f.skipped, u64::from(W * H), "{what}");
            assert_eq!(f.samples_passed, truth.full.stats.samples_passed, "{what}");
            assert_eq!(f.fragments_generated, 0, "{what}");
            assert_eq!(r.full.passes.len(), 1, "{what}");
            assert!(r.full.passes[0].full_screen, "{what}");
        }
    }
}

#[test]
fn empty_tiles_hold_the_declared_output_when_read_back_and_when_written_again() {
    // A resolve's empty tiles are fast-cleared to its declared output (nothing written
    // until the tile is read back or written again): the image, a pixel read alone, and a
    // later pass that writes one column of every tile find the declared output elsewhere.
    let empty = [7, 8, 9, 10];
    let mut execs = all_execs();
    execs.extend(direct_execs());
    for exec in &execs {
        for then in [None, Some([1, 2, 3, 4])] {
            let r = run_with(exec, true, true, empty, then);
            let what = format!("{exec:?}, then {then:?}");
            for (p, (texel, list)) in r.image.iter().zip(&r.lists).enumerate() {
                let want = match then {
                    Some(v) if (p as u32).is_multiple_of(W) => v,
                    _ if list.is_empty() => empty,
                    _ => [list.len() as u32, list.iter().map(|id| id + 1).sum(), 0, 0],
                };
                assert_eq!(*texel, want, "{what}: pixel {p}");
            }
        }
    }
    // The screen's second column of blocks (32 pixels wide, x >= 32) and so its tiles
    // (8 pixels) are empty: the fast-cleared tiles the loop above read back and wrote.
    let r = run_with(&ExecConfig::ordered(), true, true, empty, None);
    assert!((0..W * H)
        .filter(|p| p % W >= 32)
        .all(|p| r.lists[p as usize].is_empty()));
}

#[test]
fn the_general_path_marks_the_blocks_its_geometry_reaches_and_its_resolve_skips_the_rest() {
    // The scheduled executor (and contention counting) run a draw and a full-screen pass on
    // the general path, not the fused one: its rasterizer marks the blocks the draw reaches,
    // and the resolve then runs only there, writing its declared output to the other
    // blocks' pixels as the fused path does: the ordered executor's image, lists and counts.
    let empty = [7, 8, 9, 10];
    let truth = run_with(&ExecConfig::ordered(), false, false, empty, None);
    let (skipped, shaded) = (truth.full.stats.skipped, truth.full.stats.shaded);
    assert!(skipped > 0 && shaded > 0, "{skipped} skipped, {shaded} run");
    let mut execs: Vec<ExecConfig> = all_execs()
        .into_iter()
        .filter(|e| matches!(e.mode, ExecMode::Scheduled(_)))
        .collect();
    execs.push(ExecConfig {
        contention: true,
        lockstep: false,
        ..ExecConfig::parallel(2)
    });
    assert!(execs.len() >= 3);
    for exec in &execs {
        let r = run_with(exec, false, false, empty, None);
        let what = format!("{:?}", exec.mode);
        assert_eq!(r.lists, truth.lists, "{what}");
        assert_eq!(r.image, truth.image, "{what}");
        let f = &r.full.stats;
        assert_eq!((f.skipped, f.shaded), (skipped, shaded), "{what}");
        assert_eq!(f.samples_passed, truth.full.stats.samples_passed, "{what}");
        // The declared output at every pixel no fragment reached, skipped or run.
        for (p, (texel, list)) in r.image.iter().zip(&r.lists).enumerate() {
            if list.is_empty() {
                assert_eq!(*texel, empty, "{what}: pixel {p}");
            }
        }
    }
}
