//! Extracts the digital surface of a ball in a 256^3 volume (for profiling).
use voxreg_digisurf::{DigitalSurface, LabelVolume};

fn main() {
    let n = 256;
    let v = LabelVolume::from_fn([n, n, n], |[x, y, z]| {
        let d = |c: usize| c as f64 - 127.5;
        u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 100.0f64.powi(2))
    });
    let t = std::time::Instant::now();
    let s = DigitalSurface::from_volume(&v).unwrap();
    println!("{} surfels in {:?}", s.num_surfels(), t.elapsed());
}
