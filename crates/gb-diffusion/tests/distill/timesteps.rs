//! Timestep sampling, the annealed reference schedule, and w(t).

use gb_diffusion::distill::timestep::{fraction_to_index, weight};
use gb_diffusion::distill::{AlphasCumprod, TimestepConfig, Weighting};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[test]
fn uniform_sampling_covers_20_to_980() {
    let cfg = TimestepConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let samples: Vec<usize> = (0..20000).map(|i| cfg.sample(i, 1000, &mut rng)).collect();
    assert_eq!(*samples.iter().min().unwrap(), 20);
    assert_eq!(*samples.iter().max().unwrap(), 980);
    let mean = samples.iter().sum::<usize>() as f64 / samples.len() as f64;
    assert!((mean - 500.0).abs() < 5.0, "mean {mean}");
}

#[test]
fn annealed_schedule_is_980_minus_960_sqrt() {
    let cfg = TimestepConfig::reference_annealed();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for i in [0usize, 1, 50, 5000, 12345, 19999, 20000, 30000] {
        let expected = (980.0 - 960.0 * (i.min(20000) as f64 / 20000.0).sqrt()).round() as usize;
        assert_eq!(cfg.sample(i, 1000, &mut rng), expected, "i = {i}");
    }
    assert_eq!(cfg.sample(5000, 1000, &mut rng), 500);
}

#[test]
fn weight_and_sd_schedule() {
    let ab = AlphasCumprod::stable_diffusion();
    assert_eq!(ab.len(), 1000);
    assert!((ab.at(0) - 0.99915).abs() < 1e-12);
    // diffusers' SD 1.5 scheduler: alphas_cumprod[999] = 0.0046600...
    assert!((ab.at(999) - 0.00466).abs() < 5e-5, "{}", ab.at(999));
    assert!((weight(Weighting::OneMinusAlphaBar, ab.at(500)) - (1.0 - ab.at(500))).abs() < 1e-15);
    assert_eq!(weight(Weighting::Constant, ab.at(500)), 1.0);
    assert_eq!(fraction_to_index(0.5, 1000).unwrap(), 500);
    assert!(AlphasCumprod::new(&[0.9, 1.5]).is_err());
    assert!(AlphasCumprod::new(&[0.5]).is_err());
    assert_eq!(AlphasCumprod::new(&[0.9, 0.5]).unwrap().at(1), 0.5);
}
