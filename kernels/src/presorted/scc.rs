//! Strongly connected components of a directed graph (Tarjan's algorithm, iterative): the
//! instances of one component occlude one another in a cycle; the components themselves
//! are ordered by the condensation, which is acyclic.

/// The components of the graph of `n` nodes with `succ(v)` the targets of `v`'s edges (in
/// order; read once per node, so the occlusion graph needs no copy of its edges), in
/// reverse topological order of the condensation: for an edge `x -> y`, `y`'s component is
/// listed no later than `x`'s. For the occlusion graph (`x -> y`: `x` occludes `y`) that is
/// draw order, back to front.
pub fn components<I: Iterator<Item = usize>>(
    n: usize,
    succ: impl Fn(usize) -> I,
) -> Vec<Vec<usize>> {
    let mut index = vec![usize::MAX; n];
    let mut low = vec![0usize; n];
    let mut on_stack = vec![false; n];
    let mut stack: Vec<usize> = Vec::new();
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut next = 0usize;
    // The recursion as a stack of (node, its edges not yet followed).
    let mut calls: Vec<(usize, I)> = Vec::new();
    for root in 0..n {
        if index[root] != usize::MAX {
            continue;
        }
        index[root] = next;
        low[root] = next;
        next += 1;
        stack.push(root);
        on_stack[root] = true;
        calls.push((root, succ(root)));
        while let Some((v, edges)) = calls.last_mut() {
            let v = *v;
            if let Some(w) = edges.next() {
                if index[w] == usize::MAX {
                    index[w] = next;
                    low[w] = next;
                    next += 1;
                    stack.push(w);
                    on_stack[w] = true;
                    calls.push((w, succ(w)));
                } else if on_stack[w] {
                    low[v] = low[v].min(index[w]);
                }
                continue;
            }
            calls.pop();
            if let Some((u, _)) = calls.last() {
                low[*u] = low[*u].min(low[v]);
            }
            if low[v] == index[v] {
                let mut comp = Vec::new();
                while let Some(w) = stack.pop() {
                    on_stack[w] = false;
                    comp.push(w);
                    if w == v {
                        break;
                    }
                }
                out.push(comp);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cycle_and_a_tail_in_draw_order() {
        // 0 -> 1 -> 2 -> 0 is a cycle; 3 -> 0 (3 occludes the cycle), 2 -> 4.
        let adj: [Vec<usize>; 5] = [vec![1], vec![2], vec![0, 4], vec![0], vec![]];
        let comps = components(adj.len(), |v| adj[v].iter().copied());
        assert_eq!(comps.len(), 3);
        let pos = |x: usize| comps.iter().position(|c| c.contains(&x)).unwrap();
        let mut cyc = comps[pos(0)].clone();
        cyc.sort_unstable();
        assert_eq!(cyc, vec![0, 1, 2]);
        // Occluded first: 4 before the cycle, the cycle before 3.
        assert!(pos(4) < pos(0) && pos(0) < pos(3));
    }
}
