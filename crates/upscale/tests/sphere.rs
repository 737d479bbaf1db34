//! Upscaling a regularized ball approaches the finer digitization of the true sphere.

use voxreg_digisurf::DigitalSurface;
use voxreg_normals::NormalField;
use voxreg_regularize::{Params, Regularizer, Run, SolverChoice};
use voxreg_testkit::{digitize, surfel_centre, Shape, Sphere};
use voxreg_upscale::{upscale, UpscaleParams};

#[test]
fn upscaled_ball_is_closer_to_the_sphere_than_blocks() {
    let sphere = Sphere { radius: 6.3 };
    let coarse = digitize(&sphere, 1.0);
    let s = DigitalSurface::from_volume(&coarse).unwrap();
    let normals =
        NormalField::new((0..s.num_surfels()).map(|i| sphere.normal_near(surfel_centre(&s, i))).collect());
    let mut params = Params::papers();
    params.solver.choice = SolverChoice::Direct;
    let r = Regularizer::new(s.clone()).run(Run::new(&params).from_normals(&normals)).unwrap();
    let k = 4;
    let smooth = upscale(&s, &r.positions, &coarse, &UpscaleParams { factor: k }).unwrap();
    let blocky = upscale(&s, &s.positions(), &coarse, &UpscaleParams { factor: k }).unwrap();
    // Misclassified fine voxels against the true sphere (Gauss digitization at h / K).
    let wrong = |v: &voxreg_digisurf::LabelVolume| {
        let [nx, ny, nz] = v.dims();
        let mut n = 0;
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    let c = v.voxel_centre([x as i64, y as i64, z as i64]);
                    let truth = sphere.value(c) <= 0.0;
                    n += usize::from(truth != (v.labels()[[x, y, z]] != 0));
                }
            }
        }
        n
    };
    let (ws, wb) = (wrong(&smooth), wrong(&blocky));
    eprintln!("misclassified fine voxels: regularized {ws}, blocks {wb}");
    // Measured: 2912 vs 7568 (the regularized surface is ~0.04 voxel off the sphere here).
    assert!(ws * 2 < wb, "regularized {ws} vs blocks {wb}");
}
