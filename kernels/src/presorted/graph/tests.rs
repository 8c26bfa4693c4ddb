//! Tests of the occlusion graph (`super`).

use super::super::partition::{directions, partition_region};
use super::*;

/// The graph of two horizontal triangles, a (tri 0) above b (tri 1), in the partition
/// seen from above (+z).
pub(in crate::presorted) fn stacked_pair() -> Graph {
    let b = [
        DVec3::new(-0.3, -0.3, -0.2),
        DVec3::new(0.4, -0.3, -0.2),
        DVec3::new(-0.3, 0.4, -0.2),
    ];
    let a = b.map(|p| p + DVec3::new(0.0, 0.0, 0.4));
    let tris: Arc<[[DVec3; 3]]> = vec![a, b].into();
    let dirs = directions(6).unwrap();
    let k = dirs.iter().position(|d| d.z > 0.5).unwrap();
    let budget = MemoryBudget::new(None);
    Graph::build(tris, &partition_region(&dirs, k), &budget, &|_, _| {})
        .unwrap()
        .0
}

#[test]
fn the_cone_test_rejects_only_pairs_without_an_edge() {
    // Random small triangles in the unit ball (a fixed LCG), each pair against each
    // partition of the cube: a rejection must mean an empty reduced region, and it must
    // reject many pairs (else it prunes nothing).
    let mut rnd = super::super::test_lcg();
    let tris: Vec<[DVec3; 3]> = (0..40)
        .map(|_| {
            let c = DVec3::new(rnd(), rnd(), rnd()) * 0.5;
            [0, 1, 2].map(|_| c + DVec3::new(rnd(), rnd(), rnd()) * 0.15)
        })
        .collect();
    let dirs = directions(6).unwrap();
    let (mut rejected, mut edges) = (0, 0);
    for k in 0..dirs.len() {
        let part = partition_region(&dirs, k);
        for (ia, a) in tris.iter().enumerate() {
            for (ib, b) in tris.iter().enumerate() {
                if ia == ib {
                    continue;
                }
                let (ea, eb) = (part.cut(&[facing(a, false)]), part.cut(&[facing(b, true)]));
                let occl = occlusion_planes(a, b);
                let reduced = ea.cut(&occl).intersect(&eb);
                let (sa, sb) = (bounding_sphere(a), bounding_sphere(b));
                if cone_misses(sa, sb, &ea.verts, centre(&ea))
                    || cone_misses(sa, sb, &eb.verts, centre(&eb))
                {
                    rejected += 1;
                    assert!(
                        reduced.is_empty(),
                        "pair {ia} -> {ib} rejected with an edge"
                    );
                }
                edges += usize::from(!reduced.is_empty());
            }
        }
    }
    assert!(edges > 0);
    assert!(rejected > 6 * 40 * 39 / 4, "only {rejected} pairs rejected");
}

#[test]
fn a_witness_is_found_only_for_edges_and_for_most_of_them() {
    // Random small triangles in the unit ball (a fixed LCG), each ordered pair and
    // facing in each partition of the cube: a witness must mean a non-empty reduced
    // region (the clip's answer), and it must prove most edges (else it saves nothing).
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let tris: Vec<[DVec3; 3]> = (0..30)
        .map(|_| {
            let c = DVec3::new(rnd(), rnd(), rnd()) * 0.5;
            [0, 1, 2].map(|_| c + DVec3::new(rnd(), rnd(), rnd()) * 0.1)
        })
        .collect();
    let dirs = directions(6).unwrap();
    let (mut witnessed, mut by_cone, mut edges) = (0, 0, 0);
    for k in 0..dirs.len() {
        let part = partition_region(&dirs, k);
        for (ia, a) in tris.iter().enumerate() {
            for (ib, b) in tris.iter().enumerate() {
                for (fa, fb) in [(false, false), (false, true), (true, false), (true, true)] {
                    let (ea, eb) = (part.cut(&[facing(a, fa)]), part.cut(&[facing(b, fb)]));
                    if ia == ib || ea.is_empty() || eb.is_empty() {
                        continue;
                    }
                    let occl = occlusion_planes(a, b);
                    let edge = !ea.cut(&occl).intersect(&eb).is_empty();
                    let ca = (a[0] + a[1] + a[2]) / 3.0;
                    let cb = (b[0] + b[1] + b[2]) / 3.0;
                    if has_witness(ca, cb, &occl, &ea, &eb) {
                        witnessed += 1;
                        assert!(edge, "pair {ia} -> {ib} witnessed without an edge");
                    }
                    // The proof without the occlusion region's facets.
                    let w = Witness::new(ca, cb, &ea, &eb);
                    if w.is_some_and(|w| w.proven_by_cone(a, b)) {
                        by_cone += 1;
                        assert!(edge, "pair {ia} -> {ib} proven by the cone without an edge");
                    }
                    edges += usize::from(edge);
                }
            }
        }
    }
    assert!(edges > 1000, "{edges} edges");
    assert!(
        witnessed * 2 > edges,
        "{witnessed} of {edges} edges witnessed"
    );
    assert!(
        by_cone * 10 > witnessed * 9,
        "{by_cone} of {witnessed} witnesses proven by the cone"
    );
}

/// `count` triangles of the tests' LCG from `seed`: centres in a cube of half-side 0.5,
/// vertices within `size` of their centre in each coordinate.
fn random_tris(seed: u64, count: usize, size: f64) -> Arc<[[DVec3; 3]]> {
    let mut rnd = super::super::test_lcg_from(seed);
    (0..count)
        .map(|_| {
            let c = DVec3::new(rnd(), rnd(), rnd()) * 0.5;
            [0, 1, 2].map(|_| c + DVec3::new(rnd(), rnd(), rnd()) * size)
        })
        .collect()
}

#[test]
fn a_sample_of_rows_has_the_full_graphs_edges_of_those_rows() {
    // The estimate's rows (every third node) against the whole graph: the same edges
    // leave each sampled node, in the same order.
    let tris = random_tris(0x1234_5678_9abc_def1, 24, 0.1);
    let dirs = directions(6).unwrap();
    let part = partition_region(&dirs, 0);
    let budget = MemoryBudget::new(None);
    let (full, _) = Graph::build(tris.clone(), &part, &budget, &|_, _| {}).unwrap();
    let mut sample = Graph::nodes_of(tris, &part);
    let rows: Vec<usize> = (0..sample.nodes.len()).step_by(3).collect();
    let stats = sample
        .add_rows(
            rows.iter().copied(),
            RowWork::Sequential,
            &budget,
            &|_, _| {},
        )
        .unwrap();
    let pairs = |g: &Graph| -> Vec<(u32, u32)> {
        g.edges
            .iter()
            .filter(|e| rows.contains(&(e.from as usize)))
            .map(|e| (e.from, e.to))
            .collect()
    };
    assert!(pairs(&full).len() > 10, "{} edges", pairs(&full).len());
    assert_eq!(pairs(&sample), pairs(&full));
    assert_eq!(sample.edges.len() as u64, stats.witnessed + stats.clipped);
}

#[test]
fn rows_on_many_threads_give_the_graph_of_rows_one_after_another() {
    // The same edges in the same order (ids, out-lists) and the same counts, on a pool of
    // 3 threads taking batches of rows, as one thread taking them in order.
    let tris = random_tris(0x0bad_cafe_f00d_1234, 60, 0.15);
    let dirs = directions(6).unwrap();
    let part = partition_region(&dirs, 1);
    let budget = MemoryBudget::new(None);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap();
    let (par, par_stats) = pool
        .install(|| Graph::build(tris.clone(), &part, &budget, &|_, _| {}))
        .unwrap();
    let mut seq = Graph::nodes_of(tris, &part);
    let n = seq.nodes.len();
    let seq_stats = seq
        .add_rows(0..n, RowWork::Sequential, &budget, &|_, _| {})
        .unwrap();
    assert!(par.edges.len() > 100, "{} edges", par.edges.len());
    assert_eq!(par.edges, seq.edges);
    assert_eq!(par.out, seq.out);
    assert_eq!(par_stats, seq_stats);
}

#[test]
fn two_stacked_triangles_have_the_expected_edges() {
    let g = stacked_pair();
    // From above both front copies are rendered; the back copies never are.
    assert_eq!(g.nodes.len(), 2);
    assert!(g.nodes.iter().all(|n| !n.back));
    // a (tri 0) occludes b (tri 1), never the reverse.
    assert_eq!(g.edge_count(), 1);
    let (_, e) = g.live_edges().next().unwrap();
    assert_eq!(
        (g.nodes[e.from as usize].tri, g.nodes[e.to as usize].tri),
        (0, 1)
    );
}

#[test]
fn alive_bits_round_trip_across_words() {
    let mut b = Bits::default();
    for i in 0..200 {
        b.push(i % 3 == 0);
    }
    b.set(64, true);
    b.set(63, false);
    let want: Vec<bool> = (0..200)
        .map(|i| (i % 3 == 0 || i == 64) && i != 63)
        .collect();
    assert_eq!((0..200).map(|i| b.get(i)).collect::<Vec<_>>(), want);
    assert_eq!(b.count_ones(), want.iter().filter(|&&v| v).count());
}

/// Random small triangles in the unit ball (a fixed LCG).

#[test]
fn a_graph_charges_its_bytes_and_stops_at_the_budget() {
    let tris = random_tris(super::super::TEST_LCG_SEED, 30, 0.1);
    let part = partition_region(&directions(6).unwrap(), 0);
    let free = MemoryBudget::new(None);
    let (g, stats) = Graph::build(tris.clone(), &part, &free, &|_, _| {}).unwrap();
    let edges = g.edges.len() as u64;
    assert!(edges > 10, "{edges} edges");
    // What it charged is its estimate from its edge count (each row's alive bits
    // rounded up to a byte).
    let est = g.bytes_for(edges, false);
    assert!(
        (est..=est + g.nodes.len() as u64).contains(&stats.charged),
        "{} charged, {est} estimated",
        stats.charged
    );
    assert!(stats.charged >= edges * EDGE_BYTES);
    // A budget short of it by one byte stops the build, names both figures, and keeps
    // nothing charged.
    let tight = MemoryBudget::new(Some(stats.charged - 1));
    let e = Graph::build(tris.clone(), &part, &tight, &|_, _| {}).unwrap_err();
    assert_eq!(
        e,
        GraphError::Memory {
            bytes: stats.charged,
            limit: stats.charged - 1
        }
    );
    assert!(e.to_string().contains("memory limit"), "{e}");
    assert_eq!(tight.used.load(Ordering::Relaxed), 0);
    // Exactly enough builds the same graph.
    let exact = MemoryBudget::new(Some(stats.charged));
    let (h, _) = Graph::build(tris, &part, &exact, &|_, _| {}).unwrap();
    assert_eq!(h.edges, g.edges);
}

#[test]
fn in_edges_indexed_or_not_are_the_same_and_follow_splits() {
    let tris = random_tris(super::super::TEST_LCG_SEED, 24, 0.1);
    let part = partition_region(&directions(6).unwrap(), 1);
    let budget = MemoryBudget::new(None);
    let (mut g, _) = Graph::build(tris, &part, &budget, &|_, _| {}).unwrap();
    let ins = |g: &Graph| -> Vec<Vec<Edge>> {
        (0..g.nodes.len())
            .map(|x| g.in_edges(x).copied().collect())
            .collect()
    };
    let scanned = ins(&g);
    assert!(scanned.iter().map(Vec::len).sum::<usize>() > 10);
    g.index_in_edges();
    assert_eq!(ins(&g), scanned);
    // After a split, every live edge is in its target's in-list and its source's
    // out-list, and no dead one is.
    let x = (0..g.nodes.len())
        .max_by_key(|&x| g.in_edges(x).count() + g.out_edges(x).count())
        .unwrap();
    let c = centre(&g.nodes[x].region);
    g.split(
        x,
        Plane {
            n: DVec3::X,
            d: -c.x,
        },
    );
    for y in 0..g.nodes.len() {
        let live_in: Vec<Edge> = g
            .live_edges()
            .filter(|(_, e)| e.to as usize == y)
            .map(|(_, e)| *e)
            .collect();
        assert_eq!(g.in_edges(y).copied().collect::<Vec<_>>(), live_in);
        assert!(g.in_ids(y).iter().all(|&e| g.is_alive(e as usize)));
    }
}

#[test]
fn the_cone_proves_no_witness_for_a_flat_occlusion_region() {
    // Two triangles side by side in the plane z = 0: `O_{a->b}` lies in that plane (no
    // interior), so no candidate may be proven, however deep inside the regions it is;
    // with `b` lowered by 0.01 the region has an interior and the candidates prove it.
    let a = [
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(0.1, 0.0, 0.0),
        DVec3::new(0.0, 0.1, 0.0),
    ];
    let everywhere = Region::cube(100.0);
    let proven = |b: [DVec3; 3]| {
        let (ca, cb) = ((a[0] + a[1] + a[2]) / 3.0, (b[0] + b[1] + b[2]) / 3.0);
        Witness::new(ca, cb, &everywhere, &everywhere).is_some_and(|w| w.proven_by_cone(&a, &b))
    };
    let beside = a.map(|p| p - DVec3::new(0.5, 0.2, 0.0));
    assert!(
        !proven(beside),
        "a flat occlusion region proven to have an interior"
    );
    let below = a.map(|p| p - DVec3::new(0.5, 0.2, 0.01));
    assert!(proven(below), "a solid occlusion region not proven");
    // Nearly flat: a tilt of 1e-9 leaves no room for a ball of radius WITNESS_MARGIN.
    let barely = a.map(|p| p - DVec3::new(0.5, 0.2, 1e-9));
    assert!(
        !proven(barely),
        "a sliver proven to hold a ball of radius WITNESS_MARGIN"
    );
}
