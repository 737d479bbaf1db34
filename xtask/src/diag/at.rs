//! `cargo xtask diag at-cg-tolerance`: Ambrosio-Tortorelli's CG tolerance on bunny-128.
//! CG iterations, and how far the fields lie from exact solves (CG to `1e-11`), at the
//! default `1e-5` and at `1e-6`; then the iterations without the sharpening stage.

use anyhow::Result;
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::{AmbrosioTortorelli, AtLinearSolver, AtParams, AtSolver};
use voxreg_testkit::angles_deg;

/// Mean, 99th percentile and max of `x`.
fn spread(mut x: Vec<f64>) -> (f64, f64, f64) {
    x.sort_by(f64::total_cmp);
    let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
    (mean, x[x.len() * 99 / 100], x[x.len() - 1])
}

pub(super) fn at_cg_tolerance() -> Result<()> {
    let path = crate::root().join("data/bunny-128.vol");
    let surface = DigitalSurface::from_volume(&voxreg_io::read_volume(&path)?.volume)?;
    let input = AmbrosioTortorelli::default().initial.estimate(&surface)?;
    let mut solver = AtSolver::new(&surface)?;
    let with = |tolerance: f64| AtParams {
        linear_solver: AtLinearSolver::ConjugateGradient { tolerance, max_iterations: 5000 },
        ..AtParams::default()
    };
    let (u_exact, v_exact, _) = solver.solve(&input, &with(1e-11))?;
    for tolerance in [1e-6, 1e-5] {
        let (u, v, info) = solver.solve(&input, &with(tolerance))?;
        let angle = spread(angles_deg(u.as_slice(), u_exact.as_slice()));
        let dv = spread(v.as_slice().iter().zip(v_exact.as_slice()).map(|(a, b)| (a - b).abs()).collect());
        println!(
            "CG to {tolerance:e}: {} CG iterations; u vs exact mean {:.1e} p99 {:.1e} max {:.3} degrees; v vs exact \
             mean {:.1e} p99 {:.1e} max {:.1e}; last v change per eps {:?}",
            info.cg_iterations, angle.0, angle.1, angle.2, dv.0, dv.1, dv.2, info.v_change
        );
    }
    let plain = AtParams { sharpen_iterations: 0, ..with(1e-5) };
    println!(
        "CG to 1e-5 without the sharpening stage: {} CG iterations",
        solver.solve(&input, &plain)?.2.cg_iterations
    );
    Ok(())
}
