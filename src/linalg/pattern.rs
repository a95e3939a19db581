//! The block-sparse pattern of a Hessian assembled from per-simplex blocks: `D` unknowns per
//! vertex (interleaved, row `D·v + r`), simplices of `K` corners (triangles, K = 3, in the
//! global UV solver with D = 2; tets, K = 4, in the volumetric Newton solver with D = 3).
//! Finite-element assembly as in e.g. Saad, *Iterative Methods for Sparse Linear Systems*
//! (2003), §2.3: the row of vertex a holds a D×D block for every vertex sharing a simplex
//! with a. It exists so both Newton solvers build the CSR structure once per mesh and scatter
//! every per-simplex block by precomputed positions, with no search per entry.
#![forbid(unsafe_code)]

use sprs::CsMat;

/// The vertices sharing a simplex with each vertex, ascending, deduplicated; with the vertex
/// itself when `with_self` (Hessian rows), without it (graph Laplacians).
pub fn neighbours<const K: usize>(
    nv: usize,
    simplices: &[[u32; K]],
    with_self: bool,
) -> Vec<Vec<u32>> {
    let (ptr, idx) = neighbour_lists(nv, &[simplices], with_self);
    ptr.windows(2).map(|w| idx[w[0]..w[1]].to_vec()).collect()
}

/// [`neighbours`] of the simplices of all `groups` (corners from `nv` on ignored) as one flat
/// list: vertex a's neighbours are `idx[ptr[a]..ptr[a + 1]]` (one allocation, not one per
/// vertex: the scaffold's pattern is built again after re-triangulations).
fn neighbour_lists<const K: usize>(
    nv: usize,
    groups: &[&[[u32; K]]],
    with_self: bool,
) -> (Vec<usize>, Vec<u32>) {
    // Corners from `nv` on are fixed (not unknowns): they have no rows and no blocks.
    let pairs = || {
        groups.iter().flat_map(|g| g.iter()).flat_map(move |s| {
            s.iter()
                .filter(move |&&a| (a as usize) < nv)
                .flat_map(move |&a| {
                    s.iter()
                        .filter(move |&&b| b != a && (b as usize) < nv)
                        .map(move |&b| (a, b))
                })
        })
    };
    let mut count = vec![usize::from(with_self); nv];
    for (a, _) in pairs() {
        count[a as usize] += 1;
    }
    let mut ptr = Vec::with_capacity(nv + 1);
    ptr.push(0);
    for c in &count {
        ptr.push(ptr[ptr.len() - 1] + c);
    }
    let mut idx = vec![0u32; ptr[nv]];
    let mut next = ptr[..nv].to_vec();
    if with_self {
        for (a, n) in next.iter_mut().enumerate() {
            idx[*n] = a as u32;
            *n += 1;
        }
    }
    for (a, b) in pairs() {
        idx[next[a as usize]] = b;
        next[a as usize] += 1;
    }
    let ptr = sort_dedup_lists(&ptr, &mut idx);
    (ptr, idx)
}

/// Sorts and deduplicates each list `idx[ptr[i]..ptr[i + 1]]` of a flat list of lists,
/// compacting `idx` in place (the write position never passes the read position); returns
/// the new list starts.
pub(crate) fn sort_dedup_lists<T: Ord + Copy>(ptr: &[usize], idx: &mut Vec<T>) -> Vec<usize> {
    let mut w = 0;
    let mut out = Vec::with_capacity(ptr.len());
    out.push(0);
    for l in ptr.windows(2) {
        idx[l[0]..l[1]].sort_unstable();
        let start = w;
        for k in l[0]..l[1] {
            let v = idx[k];
            if w == start || idx[w - 1] != v {
                idx[w] = v;
                w += 1;
            }
        }
        out.push(w);
    }
    idx.truncate(w);
    out
}

/// The slot of a corner pair with a fixed corner ([`BlockPattern::fixed`]): no block.
pub const FIXED: u32 = u32::MAX;

/// CSR structure of the (D·#V)² Hessian: row `D·a + r` holds columns `D·b + s` for every
/// vertex b sharing a simplex with a (a itself included), b ascending.
#[derive(Clone, Debug)]
pub struct BlockPattern<const D: usize, const K: usize> {
    /// Number of rows (= columns) D·#V.
    pub n: usize,
    pub indptr: Vec<usize>,
    pub indices: Vec<usize>,
    /// Per simplex, per corner pair (i, j): position of `s[j]` in `s[i]`'s neighbour list
    /// ([`FIXED`] when either corner is fixed).
    pub slot: Vec<[[u32; K]; K]>,
    /// Per vertex: its position in its own neighbour list (the diagonal block).
    pub diag_slot: Vec<u32>,
}

impl<const D: usize, const K: usize> BlockPattern<D, K> {
    /// The pattern of `simplices` over `nv` vertices (corners from `nv` on are fixed: no
    /// rows, no blocks, [`FIXED`] slots).
    pub fn new(nv: usize, simplices: &[[u32; K]]) -> Self {
        Self::with_extra(nv, simplices, &[])
    }

    /// The pattern of `simplices` and `extra` over `nv` vertices, with the slots of
    /// `simplices` only: `extra` reserves blocks for simplices that may replace some of them
    /// later ([`BlockPattern::rebind`]) without a new pattern.
    pub fn with_extra(nv: usize, simplices: &[[u32; K]], extra: &[[u32; K]]) -> Self {
        let (ptr, nb) = neighbour_lists(nv, &[simplices, extra], true);
        let mut pattern = Self::from_lists(nv, &ptr, &nb);
        // Neither can fail: every corner was inserted into every other's list, and every
        // vertex into its own.
        pattern.rebind(0, simplices);
        pattern.diag_slot = (0..nv as u32)
            .map(|v| pattern.find(v, v).unwrap_or(0))
            .collect();
        pattern
    }

    /// The pattern of this one's simplices (`base`, the ones its slots are for) followed by
    /// `simplices`, with blocks reserved for `extra`: what [`BlockPattern::with_extra`] gives
    /// for `base ++ simplices` and `extra`, built from this pattern. Only the rows `simplices`
    /// and `extra` add blocks to are merged, and only the slots in those rows looked up again.
    ///
    /// Why: the bijective UV solver's scaffold is re-triangulated many times per solve, and
    /// each new triangulation needs a new pattern of the chart with it; the scaffold only
    /// couples the chart's boundary vertices, so all other rows and slots are the chart's, the
    /// same every time (rebuilding them was a sixth of the scaffolded solve).
    pub fn extended(&self, base: &[[u32; K]], simplices: &[[u32; K]], extra: &[[u32; K]]) -> Self {
        let nv = self.n / D;
        let (eptr, eidx) = neighbour_lists(nv, &[simplices, extra], false);
        let mut ptr = Vec::with_capacity(nv + 1);
        let mut nb: Vec<u32> = Vec::with_capacity(self.indices.len() / (D * D) + eidx.len());
        let mut changed = vec![false; nv];
        ptr.push(0);
        for (a, grew) in changed.iter_mut().enumerate() {
            let row = &self.indices[self.indptr[D * a]..self.indptr[D * a + 1]];
            let old = row.iter().step_by(D).map(|&c| (c / D) as u32);
            let add = &eidx[eptr[a]..eptr[a + 1]];
            let start = nb.len();
            if add.is_empty() {
                nb.extend(old);
            } else {
                // Both ascending: a merge, each vertex once.
                let mut add = add.iter().copied().peekable();
                for b in old {
                    while let Some(&c) = add.peek() {
                        if c >= b {
                            break;
                        }
                        nb.push(c);
                        add.next();
                    }
                    if add.peek() == Some(&b) {
                        add.next();
                    }
                    nb.push(b);
                }
                nb.extend(add);
                *grew = nb.len() - start != row.len() / D;
            }
            ptr.push(nb.len());
        }
        let mut pattern = Self::from_lists(nv, &ptr, &nb);
        debug_assert_eq!(
            base.len(),
            self.slot.len(),
            "`base` is this pattern's simplices"
        );
        let mut slot = self.slot.clone();
        for (t, s) in base.iter().zip(slot.iter_mut()) {
            for i in 0..K {
                if pattern.fixed(t[i]) || !changed[t[i] as usize] {
                    continue;
                }
                for j in 0..K {
                    if !pattern.fixed(t[j]) {
                        s[i][j] = pattern.find(t[i], t[j]).unwrap_or(FIXED);
                    }
                }
            }
        }
        pattern.slot = slot;
        pattern.diag_slot = (0..nv as u32)
            .map(|v| match changed[v as usize] {
                true => pattern.find(v, v).unwrap_or(0),
                false => self.diag_slot[v as usize],
            })
            .collect();
        // Cannot fail: every corner of `simplices` is in every other's merged row.
        pattern.rebind(base.len(), simplices);
        pattern
    }

    /// The CSR structure of the neighbour lists `nb[ptr[a]..ptr[a + 1]]` (ascending), without
    /// slots.
    fn from_lists(nv: usize, ptr: &[usize], nb: &[u32]) -> Self {
        let n = D * nv;
        let mut indptr = Vec::with_capacity(n + 1);
        let mut indices = Vec::with_capacity(D * D * nb.len());
        indptr.push(0);
        for w in ptr.windows(2) {
            for _ in 0..D {
                for &b in &nb[w[0]..w[1]] {
                    for s in 0..D {
                        indices.push(D * b as usize + s);
                    }
                }
                indptr.push(indices.len());
            }
        }
        BlockPattern {
            n,
            indptr,
            indices,
            slot: Vec::new(),
            diag_slot: Vec::new(),
        }
    }

    /// Replaces the simplices from `first` on by `simplices` (their slots), if the pattern has
    /// a block for every pair of their corners; `false` (and nothing changed) otherwise.
    pub fn rebind(&mut self, first: usize, simplices: &[[u32; K]]) -> bool {
        let slots: Option<Vec<[[u32; K]; K]>> = simplices
            .iter()
            .map(|t| {
                let mut s = [[0u32; K]; K];
                for i in 0..K {
                    for j in 0..K {
                        s[i][j] = if self.fixed(t[i]) || self.fixed(t[j]) {
                            FIXED
                        } else {
                            self.find(t[i], t[j])?
                        };
                    }
                }
                Some(s)
            })
            .collect();
        match slots {
            Some(slots) if first <= self.slot.len() => {
                self.slot.truncate(first);
                self.slot.extend(slots);
                true
            }
            _ => false,
        }
    }

    /// Whether vertex `v` is fixed (no rows: index from `n / D` on).
    #[inline]
    pub fn fixed(&self, v: u32) -> bool {
        D * v as usize >= self.n
    }

    /// Position of vertex `b` in the neighbour list of vertex `a`, if it is there.
    fn find(&self, a: u32, b: u32) -> Option<u32> {
        let row = D * a as usize;
        let cols = self.indices.get(self.indptr[row]..self.indptr[row + 1])?;
        // Neighbour k's block starts at column entry D·k, with column D·b.
        let target = D * b as usize;
        let (mut lo, mut hi) = (0, cols.len() / D);
        while lo < hi {
            let mid = (lo + hi) / 2;
            match cols[D * mid].cmp(&target) {
                std::cmp::Ordering::Less => lo = mid + 1,
                std::cmp::Ordering::Greater => hi = mid,
                std::cmp::Ordering::Equal => return Some(mid as u32),
            }
        }
        None
    }

    /// Index in the value array of entry (D·a + r, D·b + s), b the `k`-th neighbour of a.
    #[inline]
    pub fn pos(&self, a: u32, r: usize, k: u32, s: usize) -> usize {
        self.indptr[D * a as usize + r] + D * k as usize + s
    }

    /// Index of the diagonal entry (D·v + r, D·v + r).
    #[inline]
    pub fn diag(&self, v: u32, r: usize) -> usize {
        self.pos(v, r, self.diag_slot[v as usize], r)
    }

    /// The CSR matrix of this pattern with the values `data` (one per stored entry).
    pub fn matrix(&self, data: Vec<f64>) -> CsMat<f64> {
        CsMat::new(
            (self.n, self.n),
            self.indptr.clone(),
            self.indices.clone(),
            data,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quad 0-1-2-3 split along 0–2, with the other diagonal's triangle reserved: its
    /// re-triangulation along 1–3 rebinds into the same structure, a triangle to a vertex
    /// outside it does not, and a corner from `nv` on is fixed (no row, no block).
    #[test]
    fn reserved_blocks_rebind_and_fixed_corners_have_none() {
        let faces = [[0u32, 1, 2], [0, 2, 3]];
        let mut p = BlockPattern::<2, 3>::with_extra(4, &faces, &[[1, 3, 0]]);
        assert_eq!(p.n, 8);
        // Every vertex of the quad is now a neighbour of every other: 4 blocks per row.
        for row in 0..8 {
            assert_eq!(p.indptr[row + 1] - p.indptr[row], 8);
        }
        let flipped = [[0u32, 1, 3], [1, 2, 3]];
        assert!(p.rebind(0, &flipped));
        for (t, s) in flipped.iter().zip(&p.slot) {
            for i in 0..3 {
                for j in 0..3 {
                    let pos = p.pos(t[i], 0, s[i][j], 0);
                    assert_eq!(p.indices[pos], 2 * t[j] as usize);
                }
            }
        }
        // Without the reserve, 1 and 3 share no face.
        let mut plain = BlockPattern::<2, 3>::new(4, &faces);
        assert!(!plain.rebind(0, &flipped));
        assert_eq!(plain.slot.len(), 2);
        // Vertex 4 is fixed: only the blocks among 0..4 exist.
        let q = BlockPattern::<2, 3>::new(4, &[[0u32, 1, 4], [1, 2, 4]]);
        assert_eq!(q.n, 8);
        assert!(q.fixed(4) && !q.fixed(3));
        assert_eq!(q.slot[0][0][2], FIXED);
        assert_eq!(q.slot[0][2][1], FIXED);
        assert_ne!(q.slot[0][0][1], FIXED);
        // Vertex 3 is in no face: its row holds its diagonal block only.
        assert_eq!(q.indptr[7] - q.indptr[6], 2);
    }

    /// A grid's pattern extended by triangles among its border vertices and fixed corners
    /// (a scaffold), with reserved blocks, is the pattern built from scratch: same structure,
    /// same slots, same diagonal slots.
    #[test]
    fn extended_equals_the_pattern_built_from_scratch() {
        let m = 5u32;
        let id = |i: u32, j: u32| i * m + j;
        let mut base = Vec::new();
        for i in 0..m - 1 {
            for j in 0..m - 1 {
                base.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                base.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let nv = (m * m) as usize;
        let frame = nv as u32;
        // Border vertices joined across the grid and to fixed corners from `nv` on.
        let scaffold = [
            [id(0, 0), id(0, 4), frame],
            [id(0, 4), id(4, 4), frame + 1],
            [id(4, 0), id(0, 2), id(4, 4)],
            [id(2, 0), frame, frame + 1],
        ];
        let extra = [[id(0, 1), id(4, 3), frame + 2]];
        let chart = BlockPattern::<2, 3>::new(nv, &base);
        let all: Vec<[u32; 3]> = base.iter().chain(&scaffold).copied().collect();
        let want = BlockPattern::<2, 3>::with_extra(nv, &all, &extra);
        let got = chart.extended(&base, &scaffold, &extra);
        assert_eq!(got.n, want.n);
        assert_eq!(got.indptr, want.indptr);
        assert_eq!(got.indices, want.indices);
        assert_eq!(got.slot, want.slot);
        assert_eq!(got.diag_slot, want.diag_slot);
        // The scaffold added blocks (the test exercises merged rows).
        assert!(want.indices.len() > chart.indices.len());
        // Extending with nothing is the chart's pattern.
        let same = chart.extended(&base, &[], &[]);
        assert_eq!(same.indices, chart.indices);
        assert_eq!(same.slot, chart.slot);
    }
}
