//! Augmenting paths in a general graph (Edmonds' blossoms), bounded, for the pairing of
//! triangles into quads.
//!
//! The triangles' adjacency is not bipartite: an alternating search that ignores odd
//! cycles misses augmenting paths that go round one, and leaves triangles alone that a
//! maximum matching pairs. Edmonds' search contracts each odd cycle it meets (a
//! *blossom*) into its base, so that a matching with no augmenting path found from any
//! vertex is maximum (Berge).

/// No vertex.
const NONE: u32 = u32::MAX;

/// The state of one search, reused between searches: every array is reset only where the
/// last search wrote it, so a search costs what it visits.
pub(crate) struct Blossom {
    /// The vertex an odd vertex was reached from.
    parent: Vec<u32>,
    /// Each vertex's blossom base.
    base: Vec<u32>,
    /// Whether a vertex is even (in the queue once).
    even: Vec<bool>,
    /// Marks of a blossom's bases while one is contracted.
    in_blossom: Vec<bool>,
    /// Marks of the path to the root while a common base is found.
    on_path: Vec<bool>,
    touched: Vec<u32>,
    queue: Vec<u32>,
}

impl Blossom {
    /// State for graphs of `n` vertices.
    pub(crate) fn new(n: usize) -> Self {
        Blossom {
            parent: vec![NONE; n],
            base: (0..n as u32).collect(),
            even: vec![false; n],
            in_blossom: vec![false; n],
            on_path: vec![false; n],
            touched: Vec::new(),
            queue: Vec::new(),
        }
    }

    fn touch(&mut self, v: u32) {
        if !self.even[v as usize] && self.parent[v as usize] == NONE && self.base[v as usize] == v {
            self.touched.push(v);
        }
    }

    fn reset(&mut self) {
        for &v in &self.touched {
            self.parent[v as usize] = NONE;
            self.base[v as usize] = v;
            self.even[v as usize] = false;
            self.in_blossom[v as usize] = false;
            self.on_path[v as usize] = false;
        }
        self.touched.clear();
        self.queue.clear();
    }

    /// The base of the smallest blossom holding the tree paths of `a` and `b`.
    fn common_base(&mut self, mate: &[u32], mut a: u32, mut b: u32) -> u32 {
        let mut marked = Vec::new();
        loop {
            a = self.base[a as usize];
            self.on_path[a as usize] = true;
            marked.push(a);
            if mate[a as usize] == NONE {
                break;
            }
            a = self.parent[mate[a as usize] as usize];
        }
        let found = loop {
            b = self.base[b as usize];
            if self.on_path[b as usize] {
                break b;
            }
            b = self.parent[mate[b as usize] as usize];
        };
        for v in marked {
            self.on_path[v as usize] = false;
        }
        found
    }

    fn mark_path(&mut self, mate: &[u32], mut v: u32, b: u32, mut child: u32) {
        while self.base[v as usize] != b {
            let m = mate[v as usize];
            self.in_blossom[self.base[v as usize] as usize] = true;
            self.in_blossom[self.base[m as usize] as usize] = true;
            self.parent[v as usize] = child;
            child = m;
            v = self.parent[m as usize];
        }
    }

    /// Searches an augmenting path from `root` (unmatched in `mate`, where each vertex
    /// has its partner or `u32::MAX`), visiting at most `limit` vertices; the neighbours
    /// of a vertex are `neighbours(v)`, padded with `u32::MAX`. On success the path's
    /// pairs are written to `pairs` (each to be matched both ways; the matching grows by
    /// one) and `true` is returned; `mate` is never changed.
    pub(crate) fn augmenting_path<const K: usize>(
        &mut self,
        mate: &[u32],
        root: u32,
        limit: usize,
        neighbours: impl Fn(u32) -> [u32; K],
        pairs: &mut Vec<(u32, u32)>,
    ) -> bool {
        pairs.clear();
        self.touch(root);
        self.even[root as usize] = true;
        self.queue.push(root);
        let mut head = 0;
        let mut end = NONE;
        'search: while head < self.queue.len() {
            if self.touched.len() > limit {
                break;
            }
            let v = self.queue[head];
            head += 1;
            for to in neighbours(v) {
                if to == NONE || self.base[v as usize] == self.base[to as usize] || mate[v as usize] == to {
                    continue;
                }
                let to_mate = mate[to as usize];
                if to == root || to_mate != NONE && self.parent[to_mate as usize] != NONE {
                    // An odd cycle: contract it into its base.
                    let b = self.common_base(mate, v, to);
                    self.mark_path(mate, v, b, to);
                    self.mark_path(mate, to, b, v);
                    for i in 0..self.touched.len() {
                        let w = self.touched[i];
                        if self.in_blossom[self.base[w as usize] as usize] {
                            self.base[w as usize] = b;
                            if !self.even[w as usize] {
                                self.even[w as usize] = true;
                                self.queue.push(w);
                            }
                        }
                    }
                    for i in 0..self.touched.len() {
                        let w = self.touched[i];
                        self.in_blossom[w as usize] = false;
                    }
                } else if self.parent[to as usize] == NONE {
                    self.touch(to);
                    self.parent[to as usize] = v;
                    if to_mate == NONE {
                        end = to;
                        break 'search;
                    }
                    self.touch(to_mate);
                    self.even[to_mate as usize] = true;
                    self.queue.push(to_mate);
                }
            }
        }
        if end != NONE {
            let mut v = end;
            while v != NONE {
                let pv = self.parent[v as usize];
                let next = mate[pv as usize];
                pairs.push((v, pv));
                v = next;
            }
        }
        self.reset();
        end != NONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Maximum matching size by brute force over edge subsets.
    fn brute(n: usize, edges: &[(u32, u32)]) -> usize {
        let mut best = 0;
        for mask in 0u32..(1 << edges.len()) {
            let mut used = vec![false; n];
            let mut ok = true;
            let mut c = 0;
            for (i, &(a, b)) in edges.iter().enumerate() {
                if mask >> i & 1 == 1 {
                    if used[a as usize] || used[b as usize] {
                        ok = false;
                        break;
                    }
                    used[a as usize] = true;
                    used[b as usize] = true;
                    c += 1;
                }
            }
            if ok {
                best = best.max(c);
            }
        }
        best
    }

    fn maximum(n: usize, edges: &[(u32, u32)], greedy: bool) -> usize {
        let mut adj = vec![[NONE; 4]; n];
        for &(a, b) in edges {
            for (x, y) in [(a, b), (b, a)] {
                let slot = adj[x as usize].iter().position(|&w| w == NONE).expect("degree at most 4");
                adj[x as usize][slot] = y;
            }
        }
        let mut mate = vec![NONE; n];
        if greedy {
            for &(a, b) in edges {
                if mate[a as usize] == NONE && mate[b as usize] == NONE {
                    mate[a as usize] = b;
                    mate[b as usize] = a;
                }
            }
        }
        let mut s = Blossom::new(n);
        let mut pairs = Vec::new();
        for r in 0..n as u32 {
            if mate[r as usize] == NONE
                && s.augmenting_path(&mate, r, usize::MAX, |v| adj[v as usize], &mut pairs)
            {
                for &(a, b) in &pairs {
                    mate[a as usize] = b;
                    mate[b as usize] = a;
                }
            }
        }
        for (v, &m) in mate.iter().enumerate() {
            if m != NONE {
                assert_eq!(mate[m as usize], v as u32);
                assert!(edges.contains(&(v as u32, m)) || edges.contains(&(m, v as u32)));
            }
        }
        mate.iter().filter(|&&m| m != NONE).count() / 2
    }

    #[test]
    fn a_path_round_an_odd_cycle_is_found() {
        // Triangle 0-1-2 with 1 and 2 paired and 0 alone, 5 alone joined to 1 only: the
        // path 0-2=1-5 goes round the odd cycle, which a search that marks 1 odd (reached
        // from 0) and never makes it even misses.
        let edges = [(1, 2), (0, 1), (0, 2), (1, 5)];
        assert_eq!(maximum(6, &edges, true), 2);
        assert_eq!(brute(6, &edges), 2);
    }

    #[test]
    fn searches_reach_the_maximum_on_small_graphs() {
        // Random graphs of degree at most 3 (as triangles' adjacency), from a greedy start
        // and from none: every search result is a maximum matching.
        let mut seed = 12345u64;
        let mut rnd = |m: u64| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 33) % m
        };
        for _ in 0..400 {
            let n = 4 + rnd(9) as usize;
            let mut deg = vec![0; n];
            let mut edges = Vec::new();
            for _ in 0..rnd(16) {
                let (a, b) = (rnd(n as u64) as u32, rnd(n as u64) as u32);
                if a != b
                    && deg[a as usize] < 3
                    && deg[b as usize] < 3
                    && !edges.contains(&(a, b))
                    && !edges.contains(&(b, a))
                {
                    deg[a as usize] += 1;
                    deg[b as usize] += 1;
                    edges.push((a, b));
                }
            }
            let best = brute(n, &edges);
            assert_eq!(maximum(n, &edges, true), best, "{edges:?}");
            assert_eq!(maximum(n, &edges, false), best, "{edges:?}");
        }
    }
}
