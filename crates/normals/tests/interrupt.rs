//! Interrupts: every estimator stops at a raised [`Interrupt`] and ignores one not raised.

use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_normals::{
    AmbrosioTortorelli, AtParams, ConvolvedTrivial, IntegralInvariant, Interrupt, NormalError,
    NormalEstimator, Refined, Trivial,
};

#[test]
fn every_estimator_stops_at_a_raised_interrupt_and_ignores_one_not_raised() {
    let volume = LabelVolume::from_fn([12, 12, 12], |[x, y, z]| {
        let d = |c: usize| c as f64 - 5.5;
        u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 16.0)
    });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let trivial = Trivial.estimate(&surface).unwrap();
    let positions = surface.positions();
    let estimators: Vec<Box<dyn NormalEstimator>> = vec![
        Box::new(Trivial),
        Box::new(ConvolvedTrivial { radius: None }),
        Box::new(IntegralInvariant { radius: None }),
        Box::new(AmbrosioTortorelli::new(AtParams::default(), Box::new(IntegralInvariant { radius: None }))),
        Box::new(Refined { positions: &positions, previous: &trivial, radius: 3.0, feature_angle_deg: 30.0 }),
    ];
    let raised = Interrupt::new();
    raised.raise();
    for e in &estimators {
        assert_eq!(
            e.estimate_interruptible(&surface, &raised),
            Err(NormalError::Interrupted),
            "{}",
            e.name()
        );
        let field = e.estimate_interruptible(&surface, &Interrupt::new()).unwrap();
        assert_eq!(field, e.estimate(&surface).unwrap(), "{}", e.name());
    }
}
