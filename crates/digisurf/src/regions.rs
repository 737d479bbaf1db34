//! Regions: sets of labels that count as one material.

use crate::error::SurfaceError;
use crate::ids::RegionId;
use crate::volume::{LabelStorage, LabelVolume};

/// How labels are grouped into regions.
///
/// By default every label is its own region. A caller may group labels (e.g. all
/// colours of a MagicaVoxel model into one solid, or several tissue labels into one
/// organ); labels not named in any group stay regions of their own.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RegionMap {
    groups: Vec<Vec<u32>>,
    all_in_one: bool,
}

impl RegionMap {
    /// Every label its own region.
    pub fn per_label() -> Self {
        Self::default()
    }

    /// Every non-background label in one region (one surface around all solid voxels).
    pub fn single_solid() -> Self {
        RegionMap { groups: Vec::new(), all_in_one: true }
    }

    /// Explicit groups of labels; a label may appear in at most one group.
    pub fn from_groups(groups: Vec<Vec<u32>>) -> Result<Self, SurfaceError> {
        let mut seen: Vec<u32> = groups.iter().flatten().copied().collect();
        seen.sort_unstable();
        if let Some(w) = seen.windows(2).find(|w| w[0] == w[1]) {
            return Err(SurfaceError::InvalidRegions(format!("label {} appears in two groups", w[0])));
        }
        if groups.iter().any(|g| g.is_empty()) {
            return Err(SurfaceError::InvalidRegions("empty label group".into()));
        }
        Ok(RegionMap { groups, all_in_one: false })
    }

    /// Parses groups written as `"1,2,3;7"`: groups separated by `;`, labels by `,`
    /// (one trailing `;` allowed). An empty text, an empty group (`"1;;2"`, `";"`) or an
    /// empty label (`"1,,2"`) is an error.
    pub fn parse(text: &str) -> Result<Self, SurfaceError> {
        let body = text.trim();
        let body = body.strip_suffix(';').unwrap_or(body);
        if body.trim().is_empty() {
            return Err(SurfaceError::InvalidRegions(format!("'{text}' names no group of labels")));
        }
        let mut groups = Vec::new();
        for part in body.split(';').map(str::trim) {
            if part.is_empty() {
                return Err(SurfaceError::InvalidRegions(format!("empty group in '{text}'")));
            }
            let group = part
                .split(',')
                .map(|l| {
                    l.trim().parse::<u32>().map_err(|_| {
                        SurfaceError::InvalidRegions(format!("'{}' is not a label in '{text}'", l.trim()))
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            groups.push(group);
        }
        Self::from_groups(groups)
    }

    /// Resolves the map against the labels present in `volume`.
    pub fn resolve<S: LabelStorage>(&self, volume: &LabelVolume<S>) -> Result<Regions, SurfaceError> {
        let present: Vec<u32> = volume.label_counts().into_iter().map(|(l, _)| l).collect();
        let background = volume.background();
        // Each region is a sorted list of labels; build them, then order them.
        let mut regions: Vec<Vec<u32>> = Vec::new();
        let mut grouped: Vec<u32> = Vec::new();
        if self.all_in_one {
            let solid: Vec<u32> = present.iter().copied().filter(|&l| Some(l) != background).collect();
            if !solid.is_empty() {
                grouped.extend(&solid);
                regions.push(solid);
            }
        }
        for g in &self.groups {
            let mut g = g.clone();
            g.sort_unstable();
            grouped.extend(&g);
            regions.push(g);
        }
        grouped.sort_unstable();
        for &l in &present {
            if grouped.binary_search(&l).is_err() {
                regions.push(vec![l]);
            }
        }
        if let Some(b) = background {
            if !regions.iter().any(|r| r.contains(&b)) {
                regions.push(vec![b]);
            }
        }
        // Order: by smallest label, the background's region last, so that surfel normals
        // (lower region -> higher region) point out of solids into the background.
        regions.sort_by_key(|r| (background.is_some_and(|b| r.contains(&b)), r[0]));
        let background_region =
            background.and_then(|b| regions.iter().position(|r| r.contains(&b))).map(|i| RegionId(i as u32));

        let max_label = regions.iter().flatten().copied().max().unwrap_or(0);
        let lookup = if (max_label as usize) < (1 << 24) {
            let mut dense = vec![u32::MAX; max_label as usize + 1];
            for (i, r) in regions.iter().enumerate() {
                for &l in r {
                    dense[l as usize] = i as u32;
                }
            }
            Lookup::Dense(dense)
        } else {
            let mut sorted: Vec<(u32, u32)> =
                regions.iter().enumerate().flat_map(|(i, r)| r.iter().map(move |&l| (l, i as u32))).collect();
            sorted.sort_unstable();
            Lookup::Sorted(sorted)
        };
        Ok(Regions { labels: regions, background: background_region, lookup })
    }
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Lookup {
    Dense(Vec<u32>),
    Sorted(Vec<(u32, u32)>),
}

/// The regions of one volume: a dense numbering of label groups.
///
/// Regions are ordered by their smallest label, except that the region holding the
/// background label comes last.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Regions {
    labels: Vec<Vec<u32>>,
    background: Option<RegionId>,
    lookup: Lookup,
}

impl Regions {
    /// Number of regions.
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    /// Whether there is no region.
    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// The labels of region `r`, sorted.
    pub fn labels(&self, r: RegionId) -> &[u32] {
        &self.labels[r.index()]
    }

    /// The region holding the background label, if the volume has a background.
    pub fn background(&self) -> Option<RegionId> {
        self.background
    }

    /// The region of `label`, if the label is known to this map.
    #[inline]
    pub fn region_of(&self, label: u32) -> Option<RegionId> {
        match &self.lookup {
            Lookup::Dense(d) => d.get(label as usize).copied().filter(|&r| r != u32::MAX).map(RegionId),
            Lookup::Sorted(s) => s.binary_search_by_key(&label, |e| e.0).ok().map(|i| RegionId(s[i].1)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ordering_puts_background_last() {
        let v = LabelVolume::from_fn([4, 1, 1], |p| [0, 3, 1, 2][p[0]]);
        let r = RegionMap::per_label().resolve(&v).unwrap();
        assert_eq!(r.len(), 4);
        assert_eq!(r.region_of(1), Some(RegionId(0)));
        assert_eq!(r.region_of(3), Some(RegionId(2)));
        assert_eq!(r.region_of(0), Some(RegionId(3)));
        assert_eq!(r.background(), Some(RegionId(3)));
        assert_eq!(r.region_of(9), None);
    }

    #[test]
    fn groups_and_parse() {
        let v = LabelVolume::from_fn([5, 1, 1], |p| p[0] as u32);
        let r = RegionMap::parse("3, 1 ; 4").unwrap().resolve(&v).unwrap();
        assert_eq!(r.region_of(1), r.region_of(3));
        assert_ne!(r.region_of(1), r.region_of(4));
        assert_eq!(r.len(), 4); // {1,3}, {2}, {4}, {0}
        assert!(RegionMap::parse("1,2;2").is_err());
        assert!(RegionMap::parse("1,x").is_err());
        for bad in ["", " ", ";", ";;", "1,2;;3", "1,,2", ";1"] {
            assert!(RegionMap::parse(bad).is_err(), "'{bad}' accepted");
        }
        assert!(RegionMap::parse("1,2;3;").is_ok());
        let s = RegionMap::single_solid().resolve(&v).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s.region_of(2), Some(RegionId(0)));
    }

    #[test]
    fn huge_labels_use_sorted_lookup() {
        let v = LabelVolume::from_fn([2, 1, 1], |p| [0, 4_000_000_000][p[0]]);
        let r = RegionMap::per_label().resolve(&v).unwrap();
        assert_eq!(r.region_of(4_000_000_000), Some(RegionId(0)));
        assert_eq!(r.region_of(0), Some(RegionId(1)));
    }
}
