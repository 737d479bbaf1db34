//! Compressed lists: a list of small lists in two flat arrays.

/// A list of lists stored flat (compressed sparse rows): list `i` is
/// `items[offsets[i]..offsets[i + 1]]`, with `u32` offsets (a surface's lists hold at most
/// four items per surfel, and a surface at most `2^30 - 1` surfels).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Lists<T> {
    offsets: Vec<u32>,
    items: Vec<T>,
}

impl<T: Copy + Default> Lists<T> {
    /// Builds `n` lists from `(list, item)` pairs, keeping the pairs' order within a list.
    /// Two passes (count, then fill): linear, no sorting.
    pub(crate) fn from_pairs(n: usize, pairs: impl Fn(&mut dyn FnMut(usize, T))) -> Self {
        let mut offsets = vec![0u32; n + 1];
        pairs(&mut |i, _| offsets[i + 1] += 1);
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let mut cursor = offsets.clone();
        let mut items = vec![T::default(); offsets[n] as usize];
        pairs(&mut |i, t| {
            items[cursor[i] as usize] = t;
            cursor[i] += 1;
        });
        Lists { offsets, items }
    }
}

impl<T> Lists<T> {
    /// Builds from explicit offsets and items.
    pub(crate) fn from_parts(offsets: Vec<u32>, items: Vec<T>) -> Self {
        debug_assert_eq!(*offsets.last().unwrap_or(&0) as usize, items.len());
        Lists { offsets, items }
    }

    /// Number of lists.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Whether there is no list.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// List `i`.
    #[inline]
    pub fn get(&self, i: usize) -> &[T] {
        &self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// List `i`, mutably.
    #[inline]
    pub(crate) fn get_mut(&mut self, i: usize) -> &mut [T] {
        &mut self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Total number of items in all lists.
    pub fn total_len(&self) -> usize {
        self.items.len()
    }

    /// The offsets array (`len() + 1` entries).
    pub fn offsets(&self) -> &[u32] {
        &self.offsets
    }

    /// All items, list after list.
    pub fn items(&self) -> &[T] {
        &self.items
    }
}
