//! A polygon mesh (triangles, quads or general polygons) and its topology checks.

use std::collections::HashMap;

use glam::DVec3;
use voxreg_digisurf::DigitalSurface;

/// A polygon mesh: positions and faces given as vertex lists, counter-clockwise around
/// the outward normal. Faces are stored flat (one index array and face offsets), so a
/// triangle mesh, a quad mesh and a mesh of mixed polygons share one type.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<DVec3>,
    offsets: Vec<u32>,
    indices: Vec<u32>,
}

impl Mesh {
    /// A mesh with `positions` and no face yet.
    pub fn new(positions: Vec<DVec3>) -> Self {
        Mesh { positions, offsets: vec![0], indices: Vec::new() }
    }

    /// A triangle mesh.
    pub fn from_triangles(positions: Vec<DVec3>, triangles: &[[u32; 3]]) -> Self {
        let mut mesh = Mesh::new(positions);
        triangles.iter().for_each(|t| mesh.push_face(t));
        mesh
    }

    /// A quad mesh.
    pub fn from_quads(positions: Vec<DVec3>, quads: &[[u32; 4]]) -> Self {
        let mut mesh = Mesh::new(positions);
        quads.iter().for_each(|q| mesh.push_face(q));
        mesh
    }

    /// The quads of a digital surface (one per surfel, in surfel order, oriented as the
    /// surfels) with one position per vertex: the input surface with `surface.positions()`,
    /// or a regularized one.
    pub fn from_surface(surface: &DigitalSurface, positions: &[DVec3]) -> Self {
        let mut mesh = Mesh::new(positions.to_vec());
        for s in surface.surfels() {
            mesh.push_face(&s.vertices.map(|v| v.0));
        }
        mesh
    }

    /// Appends a face (at least 3 vertex indices, counter-clockwise around its outward
    /// normal).
    pub fn push_face(&mut self, vertices: &[u32]) {
        if self.offsets.is_empty() {
            self.offsets.push(0);
        }
        self.indices.extend_from_slice(vertices);
        self.offsets.push(self.indices.len() as u32);
    }

    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// The vertex indices of face `f`.
    pub fn face(&self, f: usize) -> &[u32] {
        &self.indices[self.offsets[f] as usize..self.offsets[f + 1] as usize]
    }

    /// The faces, in order.
    pub fn faces(&self) -> impl ExactSizeIterator<Item = &[u32]> + '_ {
        (0..self.num_faces()).map(|f| self.face(f))
    }

    /// The positions of face `f`'s vertices.
    pub fn face_positions(&self, f: usize) -> impl ExactSizeIterator<Item = DVec3> + '_ {
        self.face(f).iter().map(|&v| self.positions[v as usize])
    }

    /// The vector area of face `f` (Newell's formula): its direction is the face normal,
    /// its length the area (exact for planar polygons).
    pub fn vector_area(&self, f: usize) -> DVec3 {
        let face = self.face(f);
        let c = self.centroid(f);
        let mut a = DVec3::ZERO;
        for k in 0..face.len() {
            let p = self.positions[face[k] as usize] - c;
            let q = self.positions[face[(k + 1) % face.len()] as usize] - c;
            a += p.cross(q);
        }
        a / 2.0
    }

    /// The mean of face `f`'s vertex positions.
    pub fn centroid(&self, f: usize) -> DVec3 {
        let face = self.face(f);
        face.iter().map(|&v| self.positions[v as usize]).sum::<DVec3>() / face.len() as f64
    }

    /// The triangles of a fan around each face's first vertex, with their face index.
    pub fn fan_triangles(&self) -> impl Iterator<Item = ([u32; 3], usize)> + '_ {
        self.faces()
            .enumerate()
            .flat_map(|(f, face)| (1..face.len() - 1).map(move |k| ([face[0], face[k], face[k + 1]], f)))
    }

    /// For each undirected edge `(min, max)`, the number of faces using it.
    pub fn edge_face_counts(&self) -> HashMap<(u32, u32), u32> {
        let mut counts = HashMap::new();
        for face in self.faces() {
            for k in 0..face.len() {
                let (a, b) = (face[k], face[(k + 1) % face.len()]);
                *counts.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        counts
    }

    /// Number of distinct undirected edges.
    pub fn num_edges(&self) -> usize {
        self.edge_face_counts().len()
    }

    /// Whether every edge is shared by exactly two faces.
    pub fn is_closed(&self) -> bool {
        self.edge_face_counts().values().all(|&c| c == 2)
    }

    /// Whether every directed edge `a -> b` occurs at most once and, when the edge is
    /// shared, its neighbour uses it as `b -> a` (faces consistently oriented).
    pub fn is_consistently_oriented(&self) -> bool {
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for face in self.faces() {
            for k in 0..face.len() {
                *directed.entry((face[k], face[(k + 1) % face.len()])).or_insert(0) += 1;
            }
        }
        directed.iter().all(|(&(a, b), &c)| c == 1 && directed.get(&(b, a)).is_none_or(|&r| r == 1))
    }

    /// `V - E + F`, counting the vertices used by faces.
    pub fn euler_characteristic(&self) -> i64 {
        let mut used = vec![false; self.positions.len()];
        self.indices.iter().for_each(|&v| used[v as usize] = true);
        let v = used.iter().filter(|&&u| u).count() as i64;
        v - self.num_edges() as i64 + self.num_faces() as i64
    }

    /// The enclosed volume (divergence theorem over a fan triangulation of each face):
    /// positive for a closed mesh oriented outward.
    pub fn signed_volume(&self) -> f64 {
        let mut v = 0.0;
        for f in 0..self.num_faces() {
            let c = self.centroid(f);
            let face = self.face(f);
            for k in 0..face.len() {
                let p = self.positions[face[k] as usize];
                let q = self.positions[face[(k + 1) % face.len()] as usize];
                v += c.dot(p.cross(q));
            }
        }
        v / 6.0
    }

    /// Total area (sum of the faces' vector-area lengths).
    pub fn area(&self) -> f64 {
        (0..self.num_faces()).map(|f| self.vector_area(f).length()).sum()
    }

    /// Each vertex's distinct edge neighbours, sorted.
    pub fn vertex_neighbours(&self) -> Vec<Vec<u32>> {
        let mut nbrs = vec![Vec::new(); self.positions.len()];
        for face in self.faces() {
            for k in 0..face.len() {
                let (a, b) = (face[k], face[(k + 1) % face.len()]);
                nbrs[a as usize].push(b);
                nbrs[b as usize].push(a);
            }
        }
        for n in &mut nbrs {
            n.sort_unstable();
            n.dedup();
        }
        nbrs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube as 6 quads, oriented outward.
    fn cube() -> Mesh {
        let positions = (0..8)
            .map(|i| DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64))
            .collect();
        Mesh::from_quads(
            positions,
            &[[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]],
        )
    }

    #[test]
    fn cube_topology_and_volume() {
        let m = cube();
        assert!(m.is_closed());
        assert!(m.is_consistently_oriented());
        assert_eq!(m.euler_characteristic(), 2);
        assert!((m.signed_volume() - 1.0).abs() < 1e-12);
        assert!((m.area() - 6.0).abs() < 1e-12);
        assert_eq!(m.vector_area(0), DVec3::new(0.0, 0.0, -1.0));
        assert_eq!(m.fan_triangles().count(), 12);
        assert_eq!(m.vertex_neighbours()[0], vec![1, 2, 4]);
    }

    #[test]
    fn flipping_a_face_breaks_orientation() {
        let m = cube();
        let mut flipped = Mesh::new(m.positions.clone());
        for (f, face) in m.faces().enumerate() {
            let mut face = face.to_vec();
            if f == 3 {
                face.reverse();
            }
            flipped.push_face(&face);
        }
        assert!(flipped.is_closed());
        assert!(!flipped.is_consistently_oriented());
    }
}
