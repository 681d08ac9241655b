//! Job files that run a grid's cells on the engines clusters already have:
//!
//! - `GRID/slurm.sh`: a Slurm array job (`#SBATCH --array=0-<N-1>`), one task per cell,
//!   each running `gb-nerf ablate --grid GRID --cell $SLURM_ARRAY_TASK_ID`; submit it with
//!   `sbatch GRID/slurm.sh`, then merge with `gb-nerf ablate --grid GRID --merge`;
//! - `GRID/job.yaml`: a Kubernetes Indexed Job (`completionMode: Indexed`,
//!   `completions: N`), each pod running `--cell $JOB_COMPLETION_INDEX`. The image must hold
//!   the `gb-nerf` command; the grid folder is a PersistentVolumeClaim mounted at the grid's
//!   own path, and the scene, prior and LoRA paths written in `grid.toml` must be visible
//!   at the same paths in the pod (mount them likewise). Apply it with
//!   `kubectl apply -f GRID/job.yaml`.
//!
//! The command is the `gb-nerf` that emitted the grid (its absolute path), unless `$GB_NERF`
//! names another when the job runs (Slurm) or the image has it on its `PATH` (Kubernetes).

use std::path::{Path, PathBuf};

use gb_inpaint::run::shell_quote;
use gb_inpaint::InpaintError;

/// The engines a grid can be emitted for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    /// A Slurm array job.
    Slurm,
    /// A Kubernetes Indexed Job.
    Kubernetes,
}

impl std::str::FromStr for Engine {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "slurm" => Ok(Self::Slurm),
            "kubernetes" | "k8s" => Ok(Self::Kubernetes),
            other => Err(format!(
                "unknown engine '{other}': expected slurm or kubernetes"
            )),
        }
    }
}

/// Settings of the emitted jobs.
#[derive(Debug, Clone)]
pub struct EmitOptions {
    /// The command that runs a cell (default: this executable's path; `gb-nerf`, found on
    /// the job's `PATH`, when the path cannot be read).
    pub command: String,
    /// The container image of the Kubernetes job.
    pub image: String,
    /// CPU cores per cell.
    pub cpus: usize,
    /// GPUs per cell (0: none requested).
    pub gpus: usize,
}

impl Default for EmitOptions {
    fn default() -> Self {
        Self {
            command: std::env::current_exe()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|_| "gb-nerf".into()),
            image: "gb-nerf:latest".into(),
            cpus: 4,
            gpus: 0,
        }
    }
}

/// A name Kubernetes accepts (lowercase alphanumerics and `-`, at most 52 characters so
/// that pod names with their index suffix stay under 63): `prefix-<folder's name>`.
pub(crate) fn k8s_name(prefix: &str, dir: &Path) -> String {
    // a folder without a last component (`/`, `..`) leaves the bare prefix
    let full = match dir.file_name() {
        Some(stem) => format!("{prefix}-{}", stem.to_string_lossy().to_ascii_lowercase()),
        None => prefix.to_string(),
    };
    let mut name: String = full
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    name.truncate(52);
    name.trim_end_matches('-').to_string()
}

/// The Slurm array script of a grid of `cells` cells in `grid_dir` (absolute).
pub fn slurm_script(grid_dir: &Path, cells: usize, opts: &EmitOptions) -> String {
    let grid = grid_dir.display().to_string();
    let gpus = if opts.gpus > 0 {
        format!("#SBATCH --gpus-per-task={}\n", opts.gpus)
    } else {
        String::new()
    };
    format!(
        "#!/bin/bash\n\
         # A gb-nerf method grid: one array task per cell of {grid}/grid.toml.\n\
         # Submit: sbatch {q}/slurm.sh    Merge: gb-nerf ablate --grid {q} --merge\n\
         #SBATCH --job-name=gb-nerf-grid\n\
         #SBATCH --array=0-{last}\n\
         #SBATCH --ntasks=1\n\
         #SBATCH --cpus-per-task={cpus}\n\
         {gpus}\
         #SBATCH --output={grid}/logs/cell-%a.out\n\
         set -euo pipefail\n\
         exec \"${{GB_NERF:-{cmd}}}\" ablate --grid {q} --cell \"$SLURM_ARRAY_TASK_ID\"\n",
        q = shell_quote(&grid),
        last = cells.saturating_sub(1),
        cpus = opts.cpus,
        cmd = opts.command,
    )
}

/// The Kubernetes Indexed Job of a grid of `cells` cells in `grid_dir` (absolute).
pub fn kubernetes_job(grid_dir: &Path, cells: usize, opts: &EmitOptions) -> String {
    let grid = grid_dir.display().to_string();
    let name = k8s_name("gb-nerf-grid", grid_dir);
    let gpu_limit = if opts.gpus > 0 {
        format!("\n              nvidia.com/gpu: {}", opts.gpus)
    } else {
        String::new()
    };
    let json_str = |s: &str| serde_json::Value::from(s).to_string();
    format!(
        "# A gb-nerf method grid: one pod per cell of {grid}/grid.toml.\n\
         # Apply: kubectl apply -f job.yaml    Merge: gb-nerf ablate --grid {grid} --merge\n\
         apiVersion: batch/v1\n\
         kind: Job\n\
         metadata:\n\
         \x20 name: {name}\n\
         spec:\n\
         \x20 completionMode: Indexed\n\
         \x20 completions: {cells}\n\
         \x20 parallelism: {cells}\n\
         \x20 backoffLimit: {cells}\n\
         \x20 template:\n\
         \x20   spec:\n\
         \x20     restartPolicy: Never\n\
         \x20     containers:\n\
         \x20       - name: cell\n\
         \x20         image: {image}\n\
         \x20         command:\n\
         \x20           - /bin/sh\n\
         \x20           - -c\n\
         \x20           - {script}\n\
         \x20         resources:\n\
         \x20           requests:\n\
         \x20             cpu: \"{cpus}\"\n\
         \x20           limits:\n\
         \x20             cpu: \"{cpus}\"{gpu_limit}\n\
         \x20         volumeMounts:\n\
         \x20           - name: grid\n\
         \x20             mountPath: {mount}\n\
         \x20     volumes:\n\
         \x20       - name: grid\n\
         \x20         persistentVolumeClaim:\n\
         \x20           claimName: gb-nerf-grid\n",
        image = json_str(&opts.image),
        script = json_str(&format!(
            "exec gb-nerf ablate --grid {} --cell \"$JOB_COMPLETION_INDEX\"",
            shell_quote(&grid)
        )),
        cpus = opts.cpus,
        mount = json_str(&grid),
    )
}

/// Writes the job files of `engines` for the grid in `grid_dir` with `cells` cells; returns
/// their paths.
pub fn write_jobs(
    grid_dir: &Path,
    cells: usize,
    engines: &[Engine],
    opts: &EmitOptions,
) -> Result<Vec<PathBuf>, InpaintError> {
    let grid_dir = std::path::absolute(grid_dir).map_err(|e| InpaintError::io(grid_dir, e))?;
    let mut written = Vec::new();
    for engine in engines {
        let (file, text) = match engine {
            Engine::Slurm => {
                let logs = grid_dir.join("logs");
                std::fs::create_dir_all(&logs).map_err(|e| InpaintError::io(&logs, e))?;
                ("slurm.sh", slurm_script(&grid_dir, cells, opts))
            }
            Engine::Kubernetes => ("job.yaml", kubernetes_job(&grid_dir, cells, opts)),
        };
        written.push(write_job_file(&grid_dir.join(file), &text, *engine)?);
    }
    Ok(written)
}

/// Writes one job file atomically; a Slurm script is made executable.
pub(crate) fn write_job_file(
    path: &Path,
    text: &str,
    engine: Engine,
) -> Result<PathBuf, InpaintError> {
    gb_core::write_atomic(path, text.as_bytes()).map_err(|e| InpaintError::io(path, e))?;
    #[cfg(unix)]
    if engine == Engine::Slurm {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755))
            .map_err(|e| InpaintError::io(path, e))?;
    }
    Ok(path.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slurm_script_is_an_array_over_the_cells() {
        let opts = EmitOptions {
            command: "/opt/gb-nerf".into(),
            ..EmitOptions::default()
        };
        let s = slurm_script(Path::new("/runs/my grid"), 3, &opts);
        assert!(s.starts_with("#!/bin/bash\n"), "{s}");
        assert!(s.contains("#SBATCH --array=0-2\n"), "{s}");
        assert!(
            s.contains("--grid '/runs/my grid' --cell \"$SLURM_ARRAY_TASK_ID\""),
            "{s}"
        );
        assert!(s.contains("${GB_NERF:-/opt/gb-nerf}"), "{s}");
        assert!(!s.contains("--gpus-per-task"), "{s}");
    }

    #[test]
    fn kubernetes_names_are_valid() {
        assert_eq!(
            k8s_name("gb-nerf-grid", Path::new("/x/My_Grid.v2")),
            "gb-nerf-grid-my-grid-v2"
        );
        assert_eq!(k8s_name("gb-nerf-grid", Path::new("/")), "gb-nerf-grid");
        let long = k8s_name("gb-nerf-grid", Path::new(&"a".repeat(200)));
        assert!(long.len() <= 52 && !long.ends_with('-'), "{long}");
    }
}
