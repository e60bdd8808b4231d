//! Cycles and ordering over the data edges of a graph. Feedback edges are left out: they carry
//! the previous slice's message, so they never make a node wait on itself.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

/// A data edge: node `from` feeds node `to` (indices into the node list).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Edge {
    pub from: usize,
    pub to: usize,
    pub feedback: bool,
}

/// A cycle of non-feedback edges: `nodes[0] -> nodes[1] -> ... -> nodes[0]`, and the index
/// (in the edge list) of the edge that closes it (`nodes.last() -> nodes[0]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Cycle {
    pub nodes: Vec<usize>,
    pub closing_edge: usize,
}

/// Forward adjacency over non-feedback edges: for each node, `(edge index, target)`.
fn adjacency(n: usize, edges: &[Edge], reverse: bool) -> Vec<Vec<(usize, usize)>> {
    let mut adj = vec![Vec::new(); n];
    for (i, e) in edges.iter().enumerate().filter(|(_, e)| !e.feedback) {
        if reverse {
            adj[e.to].push((i, e.from));
        } else {
            adj[e.from].push((i, e.to));
        }
    }
    adj
}

/// Strongly connected components (Kosaraju, iterative): the component index of each node.
fn components(n: usize, edges: &[Edge]) -> Vec<usize> {
    let forward = adjacency(n, edges, false);
    let backward = adjacency(n, edges, true);
    let mut finished = Vec::with_capacity(n);
    let mut seen = vec![false; n];
    for start in 0..n {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let mut stack = vec![(start, 0usize)];
        while let Some((node, next)) = stack.pop() {
            if let Some(&(_, to)) = forward[node].get(next) {
                stack.push((node, next + 1));
                if !seen[to] {
                    seen[to] = true;
                    stack.push((to, 0));
                }
            } else {
                finished.push(node);
            }
        }
    }
    let mut component = vec![usize::MAX; n];
    let mut count = 0;
    for &start in finished.iter().rev() {
        if component[start] != usize::MAX {
            continue;
        }
        component[start] = count;
        let mut stack = vec![start];
        while let Some(node) = stack.pop() {
            for &(_, from) in &backward[node] {
                if component[from] == usize::MAX {
                    component[from] = count;
                    stack.push(from);
                }
            }
        }
        count += 1;
    }
    component
}

/// One cycle per strongly connected component that has one (a self-loop counts), each starting
/// at the component's first node in file order and as short as possible from there.
pub(crate) fn find_cycles(n: usize, edges: &[Edge]) -> Vec<Cycle> {
    let component = components(n, edges);
    let forward = adjacency(n, edges, false);
    let mut reported = vec![false; n];
    let mut cycles = Vec::new();
    for start in 0..n {
        let c = component[start];
        if reported[c] {
            continue;
        }
        // Breadth-first from `start` inside its component until an edge leads back to it.
        let mut parent: Vec<Option<usize>> = vec![None; n];
        let mut visited = vec![false; n];
        visited[start] = true;
        let mut queue = VecDeque::from([start]);
        let mut closing = None;
        'search: while let Some(node) = queue.pop_front() {
            for &(edge, to) in &forward[node] {
                if to == start {
                    closing = Some((edge, node));
                    break 'search;
                }
                if component[to] == c && !visited[to] {
                    visited[to] = true;
                    parent[to] = Some(node);
                    queue.push_back(to);
                }
            }
        }
        let Some((closing_edge, last)) = closing else {
            continue;
        };
        reported[c] = true;
        // Walk the breadth-first parents back to `start` (whose parent is none).
        let mut path = vec![last];
        let mut node = last;
        while let Some(prev) = parent[node] {
            path.push(prev);
            node = prev;
        }
        path.reverse();
        cycles.push(Cycle {
            nodes: path,
            closing_edge,
        });
    }
    cycles
}

/// Nodes ordered so that every non-feedback edge goes forward; among nodes that are ready at the
/// same time the one earlier in the file comes first. Nodes on a cycle are left out (check for
/// cycles first).
pub(crate) fn topological_order(n: usize, edges: &[Edge]) -> Vec<usize> {
    let forward = adjacency(n, edges, false);
    let mut incoming = vec![0usize; n];
    for targets in &forward {
        for &(_, to) in targets {
            incoming[to] += 1;
        }
    }
    let mut ready: BinaryHeap<Reverse<usize>> = (0..n).filter(|&i| incoming[i] == 0).map(Reverse).collect();
    let mut order = Vec::with_capacity(n);
    while let Some(Reverse(node)) = ready.pop() {
        order.push(node);
        for &(_, to) in &forward[node] {
            incoming[to] -= 1;
            if incoming[to] == 0 {
                ready.push(Reverse(to));
            }
        }
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    fn e(from: usize, to: usize) -> Edge {
        Edge {
            from,
            to,
            feedback: false,
        }
    }

    #[test]
    fn no_cycle_in_a_chain_and_file_order_kept() {
        let edges = [e(0, 2), e(2, 1), e(0, 3)];
        assert!(find_cycles(4, &edges).is_empty());
        assert_eq!(topological_order(4, &edges), [0, 2, 1, 3]);
    }

    #[test]
    fn finds_a_three_node_cycle_from_the_first_node() {
        // 0 -> 1 -> 2 -> 0, plus 3 hanging off 2.
        let edges = [e(0, 1), e(1, 2), e(2, 0), e(2, 3)];
        let cycles = find_cycles(4, &edges);
        assert_eq!(
            cycles,
            [Cycle {
                nodes: vec![0, 1, 2],
                closing_edge: 2
            }]
        );
    }

    #[test]
    fn self_loop_and_two_separate_cycles() {
        let edges = [e(0, 0), e(1, 2), e(2, 1)];
        let cycles = find_cycles(3, &edges);
        assert_eq!(
            cycles,
            [
                Cycle {
                    nodes: vec![0],
                    closing_edge: 0
                },
                Cycle {
                    nodes: vec![1, 2],
                    closing_edge: 2
                }
            ]
        );
    }

    #[test]
    fn feedback_edges_break_cycles() {
        let edges = [
            e(0, 1),
            e(1, 2),
            Edge {
                from: 2,
                to: 0,
                feedback: true,
            },
        ];
        assert!(find_cycles(3, &edges).is_empty());
        assert_eq!(topological_order(3, &edges), [0, 1, 2]);
    }

    #[test]
    fn shortest_cycle_through_the_start() {
        // 0 -> 1 -> 2 -> 3 -> 0 and the shortcut 1 -> 3.
        let edges = [e(0, 1), e(1, 2), e(2, 3), e(3, 0), e(1, 3)];
        assert_eq!(
            find_cycles(4, &edges),
            [Cycle {
                nodes: vec![0, 1, 3],
                closing_edge: 3
            }]
        );
    }
}
