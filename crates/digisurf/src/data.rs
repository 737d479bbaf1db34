//! Per-element arrays indexed by the complex's typed ids.

use std::marker::PhantomData;
use std::ops::{Deref, DerefMut, Index, IndexMut};

use crate::ids::{EdgeId, SurfelId, VertexId};

/// A typed index of the complex's cells.
pub trait Id: Copy {
    /// The index as a `usize`.
    fn index(self) -> usize;
    /// The id of index `i`.
    fn from_index(i: usize) -> Self;
}

macro_rules! impl_id {
    ($($t:ty),*) => {$(
        impl Id for $t {
            #[inline]
            fn index(self) -> usize {
                self.0 as usize
            }
            #[inline]
            fn from_index(i: usize) -> Self {
                Self(i as u32)
            }
        }
    )*};
}
impl_id!(SurfelId, VertexId, EdgeId);

/// One value per element of a kind (vertex, surfel, edge), indexed by that kind's id:
/// quantities live beside the complex, not in it (geometry-central's `VertexData<T>`).
///
/// It dereferences to a slice, so slice methods (`iter`, `len`, `par_iter`, ...) and
/// functions taking `&[T]` work unchanged; indexing takes the id (`positions[v]`) or a
/// plain `usize`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct IdVec<I, T> {
    values: Vec<T>,
    id: PhantomData<fn() -> I>,
}

/// One value per vertex.
pub type VertexData<T> = IdVec<VertexId, T>;
/// One value per surfel (quad).
pub type SurfelData<T> = IdVec<SurfelId, T>;
/// One value per edge.
pub type EdgeData<T> = IdVec<EdgeId, T>;

impl<I: Id, T> IdVec<I, T> {
    /// Wraps `values`, the value of element `i` at index `i`.
    pub fn new(values: Vec<T>) -> Self {
        IdVec { values, id: PhantomData }
    }

    /// `n` values, `f(id)` for each.
    pub fn from_fn(n: usize, f: impl FnMut(I) -> T) -> Self {
        Self::new((0..n).map(I::from_index).map(f).collect())
    }

    /// `n` copies of `value`.
    pub fn filled(n: usize, value: T) -> Self
    where
        T: Clone,
    {
        Self::new(vec![value; n])
    }

    /// The values, in id order.
    pub fn as_slice(&self) -> &[T] {
        &self.values
    }

    /// The values, in id order, mutably.
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.values
    }

    /// The underlying vector.
    pub fn into_vec(self) -> Vec<T> {
        self.values
    }

    /// `(id, value)` pairs in id order.
    pub fn iter_ids(&self) -> impl Iterator<Item = (I, &T)> {
        self.values.iter().enumerate().map(|(i, v)| (I::from_index(i), v))
    }
}

impl<I, T> Default for IdVec<I, T> {
    fn default() -> Self {
        IdVec { values: Vec::new(), id: PhantomData }
    }
}

impl<I, T> Deref for IdVec<I, T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.values
    }
}

impl<I, T> DerefMut for IdVec<I, T> {
    fn deref_mut(&mut self) -> &mut [T] {
        &mut self.values
    }
}

impl<I: Id, T> Index<I> for IdVec<I, T> {
    type Output = T;
    #[inline]
    fn index(&self, id: I) -> &T {
        &self.values[id.index()]
    }
}

impl<I: Id, T> IndexMut<I> for IdVec<I, T> {
    #[inline]
    fn index_mut(&mut self, id: I) -> &mut T {
        &mut self.values[id.index()]
    }
}

impl<I, T> Index<usize> for IdVec<I, T> {
    type Output = T;
    #[inline]
    fn index(&self, i: usize) -> &T {
        &self.values[i]
    }
}

impl<I, T> IndexMut<usize> for IdVec<I, T> {
    #[inline]
    fn index_mut(&mut self, i: usize) -> &mut T {
        &mut self.values[i]
    }
}

macro_rules! impl_range_index {
    ($($r:ty),*) => {$(
        impl<I, T> Index<$r> for IdVec<I, T> {
            type Output = [T];
            #[inline]
            fn index(&self, r: $r) -> &[T] {
                &self.values[r]
            }
        }
    )*};
}
impl_range_index!(
    std::ops::Range<usize>,
    std::ops::RangeFrom<usize>,
    std::ops::RangeTo<usize>,
    std::ops::RangeInclusive<usize>,
    std::ops::RangeFull
);

impl<I, T> From<Vec<T>> for IdVec<I, T> {
    fn from(values: Vec<T>) -> Self {
        IdVec { values, id: PhantomData }
    }
}

impl<I, T> From<IdVec<I, T>> for Vec<T> {
    fn from(v: IdVec<I, T>) -> Self {
        v.values
    }
}

impl<I, T> FromIterator<T> for IdVec<I, T> {
    fn from_iter<It: IntoIterator<Item = T>>(iter: It) -> Self {
        Vec::from_iter(iter).into()
    }
}

impl<I, T> IntoIterator for IdVec<I, T> {
    type Item = T;
    type IntoIter = std::vec::IntoIter<T>;
    fn into_iter(self) -> Self::IntoIter {
        self.values.into_iter()
    }
}

impl<'a, I, T> IntoIterator for &'a IdVec<I, T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.values.iter()
    }
}

impl<I, T: serde::Serialize> serde::Serialize for IdVec<I, T> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.values.serialize(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indexing_by_id_and_by_position_agree() {
        let mut v: VertexData<f64> = VertexData::from_fn(4, |id| id.index() as f64);
        v[VertexId(2)] += 10.0;
        assert_eq!(v[2], 12.0);
        assert_eq!(v.iter().sum::<f64>(), 16.0);
        let ids: Vec<VertexId> = v.iter_ids().map(|(id, _)| id).collect();
        assert_eq!(ids, (0..4).map(VertexId).collect::<Vec<_>>());
        let s: &[f64] = &v;
        assert_eq!(s.len(), 4);
    }
}
