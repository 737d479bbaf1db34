//! One multigrid-CG solve on a digitized sphere, for instruction counts per iteration:
//! `cg_iteration_cost RADIUS ITERATIONS` runs exactly `ITERATIONS` iterations (a tolerance
//! no solve reaches); `cg_iteration_cost RADIUS` solves to the default tolerance. Prints
//! the vertices, the iterations and a checksum of the positions. `bench/speed/cg_iteration.py`
//! runs it under cachegrind and takes differences. `VOXREG_MG=steps,coarse_steps,damping`
//! replaces the multigrid defaults (to weigh a cheaper cycle against more iterations).
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::NormalField;
use voxreg_regularize::{CgParams, CgSolver, Energy, EnergyParams, MultigridParams, SolveRequest};
use voxreg_testkit::{digitize, true_normals, Sphere};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let radius: f64 = args.get(1).map_or(60.0, |a| a.parse().expect("RADIUS: a number"));
    let iterations: Option<usize> = args.get(2).map(|a| a.parse().expect("ITERATIONS: an integer"));
    let sphere = Sphere { radius };
    let s = DigitalSurface::from_volume(&digitize(&sphere, 1.0)).expect("a surface");
    let normals = NormalField::new(true_normals(&s, &sphere));
    let input = s.positions();
    let energy = Energy::new(&s, &normals, &input, EnergyParams::default()).expect("an energy");
    let mut multigrid = MultigridParams::default();
    if let Ok(mg) = std::env::var("VOXREG_MG") {
        let v: Vec<f64> = mg.split(',').map(|x| x.parse().expect("VOXREG_MG: numbers")).collect();
        multigrid.smoothing_steps = v[0] as usize;
        multigrid.coarse_smoothing_steps = v[1] as usize;
        multigrid.damping = v[2];
    }
    let params = match iterations {
        Some(k) => CgParams { tolerance: 1e-30, max_iterations: k, multigrid, ..CgParams::default() },
        None => CgParams { multigrid, ..CgParams::default() },
    };
    let mut solver = CgSolver::for_surface(&s, params).expect("a solver");
    let (x, info) = solver.solve(&energy, SolveRequest::default()).expect("a solve");
    let sum: f64 = x.iter().map(|p| p.x + 2.0 * p.y + 3.0 * p.z).sum();
    println!("vertices {} iterations {} checksum {sum:.9}", s.num_vertices(), info.iterations);
}
