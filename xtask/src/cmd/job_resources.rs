//! The resources of emitted cluster jobs, shared by `ablate --emit` and `finetune --emit`.

use gb_grid::emit::EmitOptions;

/// Container image, cores and GPUs of the emitted jobs.
#[derive(clap::Args, Debug, Clone)]
pub struct JobResources {
    /// Container image of the Kubernetes job.
    #[arg(long, default_value = "gb-nerf:latest")]
    pub image: String,
    /// CPU cores per cell (ablate) or rank (finetune) in the job files.
    #[arg(long, default_value_t = 4)]
    pub cpus: usize,
    /// GPUs per cell (ablate) or rank (finetune) in the job files.
    #[arg(long, default_value_t = 0)]
    pub gpus: usize,
}

impl JobResources {
    /// The emission options with these resources.
    pub fn emit_options(&self) -> EmitOptions {
        EmitOptions {
            image: self.image.clone(),
            cpus: self.cpus,
            gpus: self.gpus,
            ..EmitOptions::default()
        }
    }
}
