//! Typed indices of the cells of a digital surface.

macro_rules! id_type {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
        pub struct $name(pub u32);

        impl $name {
            /// The index as a `usize`, for indexing per-element arrays.
            #[inline]
            pub fn index(self) -> usize {
                self.0 as usize
            }
        }
    };
}

id_type!(
    /// Index of a surfel (a voxel face between two regions): a quad of the surface.
    SurfelId
);
id_type!(
    /// Index of a vertex (a lattice corner incident to a surfel).
    VertexId
);
id_type!(
    /// Index of an edge (a lattice edge incident to a surfel).
    EdgeId
);
id_type!(
    /// Index of an interface (the surfels between one unordered pair of regions).
    InterfaceId
);
id_type!(
    /// Index of a region (a set of labels). See `Regions` for the ordering.
    RegionId
);
