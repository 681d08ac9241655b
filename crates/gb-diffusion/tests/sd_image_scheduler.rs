//! DDIM schedule and step against diffusers' `DDIMScheduler` (SD-1.5 config).

use crate::sd_image_common;

use burn::tensor::Tensor;
use gb_core::BackendKind;
use gb_diffusion::config::{PredictionType, SchedulerConfig, TimestepSpacing};
use gb_diffusion::scheduler::DdimScheduler;
use sd_image_common::{fixture, max_abs_err, read_f32, tensor4};

const IO: &str = "scheduler_io.safetensors";

fn sd15() -> SchedulerConfig {
    SchedulerConfig::from_file(&fixture("pipeline/scheduler/scheduler_config.json")).unwrap()
}

#[test]
fn config_reads_sd15_scheduler() {
    let cfg = sd15();
    assert_eq!(cfg, SchedulerConfig::default());
}

#[test]
fn alphas_cumprod_and_timesteps_match_diffusers() {
    let mut s = DdimScheduler::new(sd15());
    let (want, _) = read_f32(IO, "alphas_cumprod");
    assert_eq!(s.alphas_cumprod.len(), 1000);
    let err = s
        .alphas_cumprod
        .iter()
        .zip(&want)
        .map(|(a, b)| (*a as f32 - b).abs())
        .fold(0.0, f32::max);
    assert!(err < 2e-6, "alphas_cumprod max abs err {err}");
    for steps in [50usize, 7] {
        s.set_timesteps(steps).unwrap();
        let (want, _) = read_f32(IO, &format!("timesteps_{steps}"));
        let got: Vec<f32> = s.timesteps.iter().map(|&t| t as f32).collect();
        assert_eq!(got, want, "{steps} steps");
    }
    for (spacing, name) in [
        (TimestepSpacing::Trailing, "trailing"),
        (TimestepSpacing::Linspace, "linspace"),
    ] {
        let mut s = DdimScheduler::new(SchedulerConfig {
            timestep_spacing: spacing,
            ..sd15()
        });
        s.set_timesteps(7).unwrap();
        let (want, _) = read_f32(IO, &format!("timesteps_7_{name}"));
        let got: Vec<f32> = s.timesteps.iter().map(|&t| t as f32).collect();
        assert_eq!(got, want, "{name} spacing");
    }
    assert!(s.set_timesteps(0).is_err());
    assert!(s.set_timesteps(1001).is_err());
}

#[test]
fn ddim_step_matches_diffusers_for_epsilon_and_v() {
    let device = BackendKind::Flex.device();
    let x = tensor4(IO, "x", &device);
    let m = tensor4(IO, "model_output", &device);
    for (pred, name) in [
        (PredictionType::Epsilon, "epsilon"),
        (PredictionType::VPrediction, "v_prediction"),
    ] {
        let mut s = DdimScheduler::new(SchedulerConfig {
            prediction_type: pred,
            ..sd15()
        });
        s.set_timesteps(50).unwrap();
        let ts = s.timesteps.clone();
        for t in [ts[0], ts[25], ts[49]] {
            let prev = s.step(m.clone(), t, x.clone()).unwrap();
            let (want, shape) = read_f32(IO, &format!("step_{name}_{t}"));
            let err = max_abs_err(prev, &want, &shape);
            assert!(err < 1e-5, "{name} t={t}: {err}");
        }
    }
}

#[test]
fn add_noise_matches_diffusers() {
    let device = BackendKind::Flex.device();
    let s = DdimScheduler::new(sd15());
    let x: Tensor<4> = tensor4(IO, "x", &device).repeat_dim(0, 3);
    let n: Tensor<4> = tensor4(IO, "noise", &device).repeat_dim(0, 3);
    let noisy = s.add_noise(x, n, &[1, 500, 999]).unwrap();
    let (want, shape) = read_f32(IO, "add_noise");
    let err = max_abs_err(noisy, &want, &shape);
    assert!(err < 1e-5, "add_noise: {err}");
    let x = tensor4(IO, "x", &device);
    assert!(s.add_noise(x.clone(), x, &[1000]).is_err());
}
