//! Random inpainting masks: coverage always inside the configured range, spread over it,
//! every shape kind reachable, deterministic per seed.

use gb_finetune::masks::{coverage, MaskConfig, MaskGenerator, MaskKind};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[test]
fn coverage_stays_in_range_and_spreads_over_it_for_every_kind() {
    let cfg = MaskConfig::default();
    assert_eq!((cfg.min_coverage, cfg.max_coverage), (0.05, 0.6));
    let gen = MaskGenerator::new(cfg.clone()).unwrap();
    let (w, h) = (64, 64);
    for kind in MaskKind::ALL {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut covs = Vec::with_capacity(500);
        for _ in 0..500 {
            let m = gen.sample_kind(&mut rng, kind, w, h);
            assert_eq!(m.len(), w * h);
            assert!(m.iter().all(|&v| v == 0.0 || v == 1.0));
            let c = coverage(&m);
            assert!(
                c >= cfg.min_coverage && c <= cfg.max_coverage,
                "{kind}: coverage {c} outside [{}, {}]",
                cfg.min_coverage,
                cfg.max_coverage
            );
            covs.push(c);
        }
        let low = covs.iter().filter(|&&c| c < cfg.min_coverage + 0.1).count();
        let high = covs
            .iter()
            .filter(|&&c| c > cfg.max_coverage - 0.15)
            .count();
        let mean = covs.iter().sum::<f32>() / covs.len() as f32;
        println!("{kind}: {low} below min+0.1, {high} above max-0.15, mean {mean:.3}");
        assert!(low >= 25, "{kind}: only {low} of 500 small masks");
        assert!(high >= 25, "{kind}: only {high} of 500 large masks");
        assert!((0.2..0.45).contains(&mean), "{kind}: mean coverage {mean}");
    }
}

#[test]
fn masks_are_deterministic_per_seed_and_mix_kinds() {
    let gen = MaskGenerator::new(MaskConfig::default()).unwrap();
    let draw = |seed: u64| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..20)
            .map(|_| gen.sample(&mut rng, 48, 40))
            .collect::<Vec<_>>()
    };
    assert_eq!(draw(5), draw(5));
    assert_ne!(draw(5), draw(6));
    // custom range and a single kind hold on a non-square image
    let gen = MaskGenerator::new(MaskConfig {
        min_coverage: 0.2,
        max_coverage: 0.3,
        kinds: vec![MaskKind::Strokes],
    })
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..200 {
        let c = coverage(&gen.sample(&mut rng, 80, 30));
        assert!((0.2..=0.3).contains(&c), "{c}");
    }
}

#[test]
fn shapes_look_like_their_kind() {
    // a rectangle mask's hole fills its bounding box; a stroke's does not
    let gen = MaskGenerator::new(MaskConfig {
        min_coverage: 0.05,
        max_coverage: 0.15,
        ..MaskConfig::default()
    })
    .unwrap();
    let (w, h) = (64, 64);
    let fill = |m: &[f32]| {
        let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
        let mut n = 0;
        for (i, &v) in m.iter().enumerate() {
            if v > 0.5 {
                let (x, y) = (i % w, i / w);
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
                n += 1;
            }
        }
        n as f32 / ((x1 - x0 + 1) * (y1 - y0 + 1)) as f32
    };
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mean_fill = |kind: MaskKind, rng: &mut ChaCha8Rng| {
        (0..100)
            .map(|_| fill(&gen.sample_kind(rng, kind, w, h)))
            .sum::<f32>()
            / 100.0
    };
    let rect = mean_fill(MaskKind::Rectangles, &mut rng);
    let ell = mean_fill(MaskKind::Ellipses, &mut rng);
    let stroke = mean_fill(MaskKind::Strokes, &mut rng);
    println!("bbox fill: rectangles {rect:.3}, ellipses {ell:.3}, strokes {stroke:.3}");
    assert!(rect > ell && ell > stroke, "{rect} {ell} {stroke}");
    assert!(stroke < 0.5, "{stroke}");
}
