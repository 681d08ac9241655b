//! Training curves from a run's `train_log.jsonl`, as SVG line charts ([`crate::svg`]).

use std::path::Path;

use crate::svg::{LineChart, Series};
use crate::ReportError;

/// At most `max` points: means over equal buckets of steps.
fn thin(points: Vec<(f64, f64)>, max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max || max == 0 {
        return points;
    }
    let per = points.len().div_ceil(max);
    points
        .chunks(per)
        .map(|c| {
            let n = c.len() as f64;
            let finite: Vec<&(f64, f64)> = c.iter().filter(|p| p.1.is_finite()).collect();
            let y = if finite.is_empty() {
                f64::NAN
            } else {
                finite.iter().map(|p| p.1).sum::<f64>() / finite.len() as f64
            };
            (c.iter().map(|p| p.0).sum::<f64>() / n, y)
        })
        .collect()
}

/// The training curves of a `train_log.jsonl`: `(file stem, chart)` for the loss (log scale),
/// the training-batch PSNR, and, when the method has guidance, the latent gradient norm of
/// each guidance term (log scale). Unparsable lines are skipped.
pub fn charts_from_log(path: &Path) -> Result<Vec<(String, LineChart)>, ReportError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReportError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let (mut loss, mut recon, mut psnr) = (Vec::new(), Vec::new(), Vec::new());
    let mut norms: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let Some(step) = v["step"].as_f64() else {
            continue;
        };
        let num = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        loss.push((step, num("loss")));
        recon.push((step, num("recon_loss")));
        psnr.push((step, num("psnr")));
        for t in v["guidance"].as_array().into_iter().flatten() {
            let name = t["modality"].as_str().unwrap_or("guidance").to_string();
            let g = t["grad_norm"].as_f64().unwrap_or(f64::NAN);
            match norms.iter_mut().find(|(n, _)| *n == name) {
                Some((_, pts)) => pts.push((step, g)),
                None => norms.push((name, vec![(step, g)])),
            }
        }
    }
    const MAX_POINTS: usize = 800;
    let mut out = Vec::new();
    let mut c = LineChart::new("training loss", "step", "loss").log_y(true);
    c.push(Series::new("total loss", thin(loss, MAX_POINTS)));
    c.push(Series::new(
        "reconstruction (unmasked)",
        thin(recon, MAX_POINTS),
    ));
    out.push(("loss".to_string(), c));
    let mut c = LineChart::new("training-batch PSNR", "step", "PSNR (dB)");
    c.push(Series::new("PSNR", thin(psnr, MAX_POINTS)));
    out.push(("psnr".to_string(), c));
    if !norms.is_empty() {
        let mut c = LineChart::new(
            "guidance: latent gradient norm",
            "step",
            "|grad| of the latents",
        )
        .log_y(true);
        for (name, pts) in norms {
            c.push(Series::new(name, thin(pts, MAX_POINTS)));
        }
        out.push(("guidance_grad_norm".to_string(), c));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charts_read_the_log_and_thin_long_ones() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("train_log.jsonl");
        std::fs::write(
            &p,
            "{\"step\":0,\"loss\":0.5,\"recon_loss\":0.4,\"psnr\":10.0,\"guidance\":[{\"modality\":\"rgb\",\"grad_norm\":0.1}]}\n\
             {\"step\":1,\"loss\":null,\"recon_loss\":null,\"psnr\":11.0,\"guidance\":[]}\n\
             not json\n",
        )
        .unwrap();
        let charts = charts_from_log(&p).unwrap();
        let names: Vec<&str> = charts.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["loss", "psnr", "guidance_grad_norm"]);
        assert_eq!(charts[1].1.series[0].points, vec![(0.0, 10.0), (1.0, 11.0)]);
        assert!(charts[0].1.series[0].points[1].1.is_nan());

        assert_eq!(thin((0..10).map(|i| (i as f64, 1.0)).collect(), 5).len(), 5);
    }
}
