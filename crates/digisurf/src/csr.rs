//! Compressed lists: a list of small lists in two flat arrays.

#[cfg(test)]
use rayon::prelude::*;

/// A list of lists stored flat (compressed sparse rows): list `i` is
/// `items[offsets[i]..offsets[i + 1]]`, with `u32` offsets (a surface's lists hold at most
/// four items per surfel, and a surface at most `2^30 - 1` surfels).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Lists<T> {
    offsets: Vec<u32>,
    items: Vec<T>,
}

impl<T: Copy + Default> Lists<T> {
    #[cfg(test)]
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

#[cfg(test)]
impl<T: Copy + Default + Send + Sync> Lists<T> {
    /// Builds `n` lists, list `i` being what `list(i, out)` pushes onto `out` (given
    /// empty), in parallel over pieces of consecutive lists: `list` runs twice per list,
    /// to size the lists and then to fill them.
    pub(crate) fn par_from_fn(n: usize, list: impl Fn(usize, &mut Vec<T>) + Sync) -> Self {
        let mut offsets = vec![0u32; n + 1];
        offsets[1..].par_chunks_mut(PIECE).enumerate().for_each_init(Vec::new, |out, (p, lens)| {
            for (k, len) in lens.iter_mut().enumerate() {
                out.clear();
                list(p * PIECE + k, out);
                *len = out.len() as u32;
            }
        });
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let mut items = vec![T::default(); offsets[n] as usize];
        let ranges: Vec<(usize, usize)> = (0..n).step_by(PIECE).map(|s| (s, (s + PIECE).min(n))).collect();
        let pieces =
            split_lengths(&mut items, ranges.iter().map(|&(s, e)| (offsets[e] - offsets[s]) as usize));
        ranges.into_par_iter().zip(pieces).for_each_init(Vec::new, |out, ((start, end), piece)| {
            let mut at = 0;
            for i in start..end {
                out.clear();
                list(i, out);
                piece[at..at + out.len()].copy_from_slice(out);
                at += out.len();
            }
        });
        Lists { offsets, items }
    }
}

/// Lists per piece of [`Lists::par_from_fn`].
pub(crate) const PIECE: usize = 4096;

#[cfg(test)]
/// `slice` cut into consecutive parts of the given lengths (for filling them in parallel).
pub(crate) fn split_lengths<T>(
    mut slice: &mut [T],
    lengths: impl IntoIterator<Item = usize>,
) -> Vec<&mut [T]> {
    let mut parts = Vec::new();
    for len in lengths {
        let (head, tail) = std::mem::take(&mut slice).split_at_mut(len);
        parts.push(head);
        slice = tail;
    }
    parts
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
