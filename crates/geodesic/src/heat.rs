//! The heat method (Crane, Weischedel and Wardetzky 2013): geodesic distance from the
//! heat flow of a short time `t`, by two sparse Cholesky solves.

use faer::linalg::solvers::Solve as _;
use faer::sparse::{linalg::solvers::Llt, SparseColMat, Triplet};
use faer::{MatMut, Side};
use glam::DVec3;

use crate::{GeodesicError, GeodesicMesh, SurfacePoint};

/// Parameters of the heat method.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HeatParams {
    /// The time step as a multiple of `h^2`, `h` the mean edge length (Crane et al.: `1`
    /// is accurate on regular meshes; larger smooths more). Default: `1.0`.
    pub time_factor: f64,
}

impl Default for HeatParams {
    fn default() -> Self {
        HeatParams { time_factor: 1.0 }
    }
}

/// The heat method on one mesh, factorizations kept: each [`HeatSolver::distances`] is
/// two back-substitutions, a gradient and a divergence.
///
/// Spec (Crane et al., Algorithm 1): with `L` the cotan Laplacian (positive
/// semi-definite) and `M` the lumped mass matrix (a third of the adjacent triangles'
/// areas), solve `(M + t L) u = delta_sources` (one backward Euler step of the heat
/// flow, `t = time_factor h^2`), take `X = -grad u / |grad u|` per triangle, and solve
/// `L phi = -div X`; the distance is `phi` shifted to be zero at its minimum on each
/// connected component. `L` is made definite by `1e-10 tr(L) / tr(M)` times `M` (its
/// kernel, the constants per component, is removed by the shift).
pub struct HeatSolver {
    mesh: GeodesicMesh,
    heat: Llt<usize, f64>,
    poisson: Llt<usize, f64>,
    /// Per triangle: the three corners' cotangents (of the angle at corner `k`).
    cotans: Vec<[f64; 3]>,
    /// Time step used.
    time: f64,
}

impl HeatSolver {
    /// Assembles and factors both systems of `mesh`.
    pub fn new(mesh: GeodesicMesh, params: &HeatParams) -> Result<Self, GeodesicError> {
        if !(params.time_factor.is_finite() && params.time_factor > 0.0) {
            return Err(GeodesicError::InvalidParams(format!(
                "time_factor {} must be positive",
                params.time_factor
            )));
        }
        let n = mesh.num_vertices();
        let h = mesh.mean_edge_length();
        let time = params.time_factor * h * h;
        let mut cotans = Vec::with_capacity(mesh.triangles.len());
        let mut mass = vec![0.0; n];
        // Lower triangle of L as (row, col, value), duplicates summed by faer.
        let mut lap: Vec<(usize, usize, f64)> = Vec::with_capacity(6 * mesh.triangles.len());
        for tri in &mesh.triangles {
            let p = tri.map(|v| mesh.pos(v));
            let double_area = (p[1] - p[0]).cross(p[2] - p[0]).length().max(f64::MIN_POSITIVE);
            let cot: [f64; 3] = std::array::from_fn(|k| {
                let (a, b) = (p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]);
                a.dot(b) / double_area
            });
            cotans.push(cot);
            for k in 0..3 {
                mass[tri[k] as usize] += double_area / 6.0;
                // The side opposite corner k joins corners k+1 and k+2.
                let (i, j) = (tri[(k + 1) % 3] as usize, tri[(k + 2) % 3] as usize);
                let w = 0.5 * cot[k];
                lap.push((i.max(j), i.min(j), -w));
                lap.push((i, i, w));
                lap.push((j, j, w));
            }
        }
        let trace_l: f64 = lap.iter().filter(|e| e.0 == e.1).map(|e| e.2).sum();
        let trace_m: f64 = mass.iter().sum();
        if trace_m.is_nan() || trace_m <= 0.0 {
            return Err(GeodesicError::InvalidMesh("the mesh has no area".into()));
        }
        let shift = 1e-10 * trace_l / trace_m;
        // Vertices in no triangle get a unit diagonal so the systems stay definite.
        let isolated: Vec<usize> = (0..n).filter(|&v| mass[v] == 0.0).collect();
        let build = |scale_l: f64, scale_m: f64| -> Result<Llt<usize, f64>, GeodesicError> {
            let mut entries: Vec<Triplet<usize, usize, f64>> = lap
                .iter()
                .map(|&(i, j, w)| Triplet::new(i, j, scale_l * w))
                .chain(mass.iter().enumerate().map(|(v, &m)| Triplet::new(v, v, scale_m * m)))
                .collect();
            entries.extend(isolated.iter().map(|&v| Triplet::new(v, v, 1.0)));
            let matrix = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &entries)
                .map_err(|e| GeodesicError::Factorization(format!("{e:?}")))?;
            matrix.sp_cholesky(Side::Lower).map_err(|e| GeodesicError::Factorization(format!("{e:?}")))
        };
        let heat = build(time, 1.0)?;
        let poisson = build(1.0, shift)?;
        Ok(HeatSolver { mesh, heat, poisson, cotans, time })
    }

    /// The mesh.
    pub fn mesh(&self) -> &GeodesicMesh {
        &self.mesh
    }

    /// The time step `t` used.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Approximate geodesic distance from the nearest of `sources` (vertex indices) at
    /// every vertex; `f64::INFINITY` on components without a source.
    pub fn distances(&self, sources: &[u32]) -> Result<Vec<f64>, GeodesicError> {
        self.mesh.check_sources(sources)?;
        let mut u = vec![0.0; self.mesh.num_vertices()];
        for &s in sources {
            u[s as usize] = 1.0;
        }
        let components: Vec<u32> = sources.iter().map(|&s| self.mesh.component[s as usize]).collect();
        Ok(self.distances_of_heat(u, &components))
    }

    /// [`HeatSolver::distances`] from points anywhere on the surface: each point's unit
    /// of heat is shared among its triangle's corners by its barycentric coordinates.
    pub fn distances_from(&self, sources: &[SurfacePoint]) -> Result<Vec<f64>, GeodesicError> {
        let mesh = &self.mesh;
        mesh.check_points(sources)?;
        let mut u = vec![0.0; mesh.num_vertices()];
        let mut components = Vec::with_capacity(sources.len());
        for p in sources {
            let tri = mesh.triangles[p.triangle as usize];
            let sum: f64 = p.barycentric.iter().sum();
            for i in 0..3 {
                u[tri[i] as usize] += p.barycentric[i].max(0.0) / sum;
            }
            components.push(mesh.component[tri[0] as usize]);
        }
        Ok(self.distances_of_heat(u, &components))
    }

    /// The distances from the initial heat `u`, on the components listed.
    fn distances_of_heat(&self, mut u: Vec<f64>, components: &[u32]) -> Vec<f64> {
        let mesh = &self.mesh;
        let n = mesh.num_vertices();
        self.heat.solve_in_place(MatMut::from_column_major_slice_mut(&mut u, n, 1));

        // -div X, X the normalized negative gradient of u per triangle.
        let mut rhs = vec![0.0; n];
        for (tri, cot) in mesh.triangles.iter().zip(&self.cotans) {
            let p = tri.map(|v| mesh.pos(v));
            let normal = (p[1] - p[0]).cross(p[2] - p[0]);
            let double_area = normal.length();
            if double_area == 0.0 {
                continue;
            }
            let normal = normal / double_area;
            let mut grad = DVec3::ZERO;
            for k in 0..3 {
                let opposite = p[(k + 2) % 3] - p[(k + 1) % 3];
                grad += u[tri[k] as usize] * normal.cross(opposite);
            }
            let len = grad.length();
            if len == 0.0 || !len.is_finite() {
                continue;
            }
            let x = -grad / len;
            for k in 0..3 {
                let (j, l) = ((k + 1) % 3, (k + 2) % 3);
                // cot of the angle at l weighs the side k-j, cot at j the side k-l.
                let div = 0.5 * (cot[l] * (p[j] - p[k]).dot(x) + cot[j] * (p[l] - p[k]).dot(x));
                rhs[tri[k] as usize] -= div;
            }
        }
        self.poisson.solve_in_place(MatMut::from_column_major_slice_mut(&mut rhs, n, 1));

        let mut lowest = vec![f64::INFINITY; mesh.num_components];
        let mut has_source = vec![false; mesh.num_components];
        for &c in components {
            has_source[c as usize] = true;
        }
        for (v, &phi) in rhs.iter().enumerate() {
            let c = mesh.component[v] as usize;
            lowest[c] = lowest[c].min(phi);
        }
        rhs.iter()
            .enumerate()
            .map(|(v, &phi)| {
                let c = mesh.component[v] as usize;
                if has_source[c] {
                    phi - lowest[c]
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact_distances;

    #[test]
    fn heat_approximates_the_exact_distance_and_reuses_its_factors() {
        let (positions, quads) =
            crate::exact::tests::grid(40, |x, y| 0.2 * (3.0 * x).sin() * (2.0 * y).cos());
        let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
        let solver = HeatSolver::new(mesh.clone(), &HeatParams::default()).unwrap();
        for source in [0u32, 860] {
            let heat = solver.distances(&[source]).unwrap();
            let (exact, _) = exact_distances(&mesh, &[source]).unwrap();
            let (mut sum, mut count) = (0.0, 0);
            for v in 0..exact.len() {
                if exact[v] > 0.1 {
                    sum += (heat[v] - exact[v]).abs() / exact[v];
                    count += 1;
                }
            }
            let mean = sum / count as f64;
            assert!(mean < 0.03, "source {source}: mean relative error {mean}");
        }
        assert!(HeatSolver::new(mesh, &HeatParams { time_factor: 0.0 }).is_err());
    }
}
