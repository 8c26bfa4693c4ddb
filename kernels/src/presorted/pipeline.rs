//! One partition's preprocessing: its checkpoint read or its work done and saved; the
//! graph built, or its components read back or carried from the previous round
//! ([`super::carry`]); the cycles resolved by cells or by the paper's scan; the segment.
//! [`super::presort_with`] runs the partitions and the rounds; this file knows one
//! partition only.

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;

use super::{
    carry, cells, checkpoint, geom, graph, order, partition, scan, Frame3, Instance, Method,
    PartitionStats, PresortError, Progress, Segment,
};

/// One partition of the input: the pieces, the partitions' directions, which one, and the
/// mesh's frame.
pub(super) struct Part<'a> {
    pub(super) tris: &'a Arc<[[DVec3; 3]]>,
    pub(super) dirs: &'a [DVec3],
    pub(super) k: usize,
    pub(super) frame: &'a Frame3,
}

/// The previous round's pieces, and how this round's came from them.
pub(super) struct Previous {
    pub(super) tris: Arc<[[DVec3; 3]]>,
    pub(super) lineage: carry::Lineage,
}

/// Where a partition's work can be read from: the checkpoints, and (with them) the
/// previous round's components to carry.
#[derive(Clone, Copy)]
pub(super) struct Store<'a> {
    pub(super) checkpoints: Option<&'a checkpoint::Checkpoints>,
    pub(super) previous: Option<&'a Previous>,
}

/// One partition read from its checkpoint when a valid one is there, else computed
/// (its failure reported to `progress` as it happens) and, when it succeeds, saved.
pub(super) fn partition_with(
    part: &Part,
    method: Method,
    budget: &graph::MemoryBudget,
    store: Store,
    progress: &dyn Progress,
) -> Result<(Segment, PartitionStats), PresortError> {
    let k = part.k;
    let key = store.checkpoints.map(|checkpoints| {
        let key = checkpoint::Checkpoints::key(&checkpoint::KeyInput {
            tris: part.tris,
            partitions: part.dirs.len(),
            partition: k,
            method,
        });
        (checkpoints, key)
    });
    let run = || {
        let r = match method {
            Method::Cells => cells_partition(part, budget, key, store.previous, progress),
            Method::Scan => scan_partition(part, budget, progress),
        };
        if let Err(e) = &r {
            progress.failed(k, e);
        }
        r
    };
    let Some((store, key)) = key else {
        return run();
    };
    match store.load(k, key, part.tris.len() as u32) {
        Some(Ok(done)) => {
            progress.update(k, "resumed", 1, 1);
            return Ok(done);
        }
        Some(Err(_)) => progress.update(k, "checkpoint ignored", 1, 1),
        None => {}
    }
    let done = run()?;
    store
        .save(k, key, &done.0, &done.1)
        .map_err(PresortError::Checkpoint)?;
    Ok(done)
}

/// One partition by the paper's scan: graph (its bytes charged to `budget` until the
/// segment is made, with the scan's index of in-edges), preliminary order, scan, and the
/// segment.
fn scan_partition(
    part: &Part,
    budget: &graph::MemoryBudget,
    progress: &dyn Progress,
) -> Result<(Segment, PartitionStats), PresortError> {
    let (k, dirs) = (part.k, part.dirs);
    let t0 = Instant::now();
    let region = partition::partition_region(dirs, k);
    let graph_error = |error| PresortError::Graph {
        partition: k,
        error,
    };
    let (mut g, rows) = graph::Graph::build(part.tris.clone(), &region, budget, &|d, t| {
        progress.update(k, "graph", d, t)
    })
    .map_err(graph_error)?;
    let in_bytes = g.edges.len() as u64 * graph::IN_EDGE_BYTES;
    let charged = rows.charged;
    let result = budget.charge(in_bytes).map_err(graph_error).and_then(|()| {
        let mut stats = PartitionStats {
            initial_nodes: g.nodes.len(),
            edges: g.edge_count(),
            graph_time: t0.elapsed(),
            ..Default::default()
        };
        let t1 = Instant::now();
        // A viewpoint of the partition: out along its face normal.
        let eye = dirs[k] * 3.0;
        g.index_in_edges();
        let prelim = order::preliminary(&g, eye);
        stats.back_edges = order::back_edges(&g, &prelim);
        let mut sstats = scan::ScanStats::default();
        let final_order = scan::scan(&mut g, prelim, &mut sstats, &|d, t| {
            progress.update(k, "scan", d, t)
        });
        budget.release(in_bytes);
        let final_order = final_order.map_err(|error| PresortError::Scan {
            partition: k,
            error,
        })?;
        stats.scan = sstats;
        stats.scan_time = t1.elapsed();
        let placed: Vec<cells::Placed> = final_order.into_iter().map(|x| (x, Vec::new())).collect();
        Ok((segment_of(&g, &placed, part.frame), stats))
    });
    budget.release(charged);
    result
}

/// One partition by cells: the graph's strongly connected components (read from a
/// components checkpoint when a valid one is there, else carried from the previous
/// round's checkpoint ([`carry`]), else from the graph built here; saved when not read),
/// each cyclic one resolved into cells ([`cells`]), and the segment. The graph's nodes
/// stay charged to `budget` until the segment is made; its edges only until the
/// components are known.
fn cells_partition(
    part: &Part,
    budget: &graph::MemoryBudget,
    store: Option<(&checkpoint::Checkpoints, u64)>,
    previous: Option<&Previous>,
    progress: &dyn Progress,
) -> Result<(Segment, PartitionStats), PresortError> {
    let k = part.k;
    let t0 = Instant::now();
    let region = partition::partition_region(part.dirs, k);
    let graph_error = |error| PresortError::Graph {
        partition: k,
        error,
    };
    let cells_error = |error| PresortError::Cells {
        partition: k,
        error,
    };
    let nodes = graph::Graph::nodes_of(part.tris.clone(), &region);
    let loaded = store.and_then(
        |(s, key)| match s.load_components(k, key, nodes.nodes.len()) {
            Some(Ok(saved)) => {
                progress.update(k, "graph resumed", 1, 1);
                Some(saved)
            }
            Some(Err(_)) => {
                progress.update(k, "checkpoint ignored", 1, 1);
                None
            }
            None => None,
        },
    );
    let carried = match (store, previous, &loaded) {
        (Some((s, _)), Some(p), None) => carried(part, &region, &nodes, s, p, t0, progress),
        _ => None,
    };
    let found = match (loaded, carried) {
        (Some(saved), _) => Some((saved, None)),
        (None, Some(saved)) => Some((saved, store)),
        (None, None) => None,
    };
    let (g, parts, facts, charged) = match found {
        Some(((facts, comps, inner), save)) => {
            if let Some((s, key)) = save {
                s.save_components(k, key, &facts, &comps, &inner)
                    .map_err(PresortError::Checkpoint)?;
            }
            let charged = nodes.bytes_for(0, false);
            budget.charge(charged).map_err(graph_error)?;
            match cells::Components::charged(comps, inner, budget) {
                Ok(parts) => (nodes, parts, facts, charged),
                Err(e) => {
                    budget.release(charged);
                    return Err(cells_error(e));
                }
            }
        }
        None => {
            // The graph of these nodes (as `Graph::build` makes it, without making them again).
            let mut g = nodes;
            let n = g.nodes.len();
            let rows = g
                .add_rows(0..n, graph::RowWork::Parallel, budget, &|d, t| {
                    progress.update(k, "graph", d, t)
                })
                .map_err(graph_error)?;
            let facts = checkpoint::GraphFacts {
                nodes: g.nodes.len(),
                edges: g.edge_count(),
                graph_time: t0.elapsed(),
            };
            let (parts, freed) = match cells::components(&mut g, budget) {
                Ok(found) => found,
                Err(e) => {
                    budget.release(rows.charged);
                    return Err(cells_error(e));
                }
            };
            let freed = freed.min(rows.charged);
            budget.release(freed);
            let charged = rows.charged - freed;
            if let Some((s, key)) = store {
                let saved = s.save_components(k, key, &facts, &parts.comps, &parts.inner);
                if let Err(e) = saved {
                    budget.release(charged);
                    return Err(PresortError::Checkpoint(e));
                }
            }
            (g, parts, facts, charged)
        }
    };
    let mut stats = PartitionStats {
        initial_nodes: facts.nodes,
        edges: facts.edges,
        graph_time: facts.graph_time,
        ..Default::default()
    };
    let t1 = Instant::now();
    let placed = cells::resolve_components(&g, parts, &mut stats.cells, &|d, t| {
        progress.update(k, "scan", d, t)
    });
    let result = placed.map_err(cells_error).map(|placed| {
        stats.scan_time = t1.elapsed();
        (segment_of(&g, &placed, part.frame), stats)
    });
    budget.release(charged);
    result
}

/// The components of partition `part` (nodes `nodes` over `region`) carried from the
/// previous round's components checkpoint, if it is there and valid and every node comes
/// from one of that round's ([`carry::carry`]); reported as phase `"graph carried"`.
fn carried(
    part: &Part,
    region: &geom::Region,
    nodes: &graph::Graph,
    store: &checkpoint::Checkpoints,
    previous: &Previous,
    t0: Instant,
    progress: &dyn Progress,
) -> Option<checkpoint::SavedComponents> {
    let key = checkpoint::Checkpoints::key(&checkpoint::KeyInput {
        tris: &previous.tris,
        partitions: part.dirs.len(),
        partition: part.k,
        method: Method::Cells,
    });
    let before = graph::Graph::nodes_of(previous.tris.clone(), region);
    let (facts, comps, inner) = store
        .load_components(part.k, key, before.nodes.len())?
        .ok()?;
    let before: Vec<(u32, bool)> = before.nodes.iter().map(|x| (x.tri, x.back)).collect();
    let (comps, inner) = carry::carry(&comps, &inner, &before, nodes, &previous.lineage)?;
    progress.update(part.k, "graph carried", 1, 1);
    let facts = checkpoint::GraphFacts {
        nodes: nodes.nodes.len(),
        edges: facts.edges,
        graph_time: facts.graph_time + t0.elapsed(),
    };
    Some((facts, comps, inner))
}

/// The segment of a resolved graph: instances in draw order with their test planes (the
/// node's cuts and its cell's planes) in world space, the last copy of each triangle and
/// facing marked.
fn segment_of(g: &graph::Graph, order: &[cells::Placed], frame: &Frame3) -> Segment {
    let mut seen = std::collections::HashSet::new();
    let mut last = vec![false; order.len()];
    for (i, (x, _)) in order.iter().enumerate().rev() {
        let n = &g.nodes[*x];
        if seen.insert((n.tri, n.back)) {
            last[i] = true;
        }
    }
    let instances = order
        .iter()
        .zip(last)
        .map(|((x, cell), last)| {
            let n = &g.nodes[*x];
            Instance {
                piece: n.tri,
                back: n.back,
                last,
                planes: n
                    .cuts
                    .iter()
                    .chain(cell)
                    .map(|p| frame.world_plane(p).map(|c| c as f32))
                    .collect(),
            }
        })
        .collect();
    Segment { instances }
}
