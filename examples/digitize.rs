//! Writes a digitized analytic shape as a DGtal `.vol` volume, to try voxreg on inputs of
//! any size (Gauss digitization: voxel `p` is inside iff `f(h p) <= 0`).
//!
//! ```text
//! cargo run --release --example digitize -- sphere 250 sphere-250.vol   # radius in voxels
//! cargo run --release --example digitize -- torus 0.25 torus.vol        # R = 6, r = 2, step h
//! cargo run --release --example digitize -- goursat 0.156 goursat.vol   # step h
//! ```

use std::path::Path;

use voxreg::io::write_volume;
use voxreg_testkit::{digitize, Goursat, Shape, Sphere, Torus};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [shape, size, out] = args.as_slice() else {
        return Err(
            "usage: digitize sphere|torus|goursat SIZE OUT.vol (sphere: radius in voxels; others: grid step)"
                .into(),
        );
    };
    let size: f64 = size.parse().map_err(|_| format!("'{size}' is not a number"))?;
    let (shape, h): (Box<dyn Shape>, f64) = match shape.as_str() {
        "sphere" => (Box::new(Sphere { radius: size }), 1.0),
        "torus" => (Box::new(Torus { major: 6.0, minor: 2.0 }), size),
        "goursat" => (Box::new(Goursat), size),
        other => return Err(format!("unknown shape '{other}'").into()),
    };
    let volume = digitize(shape.as_ref(), h);
    write_volume(Path::new(out), &volume, None)?;
    let [x, y, z] = volume.dims();
    println!("{out}: {x} x {y} x {z} voxels");
    Ok(())
}
