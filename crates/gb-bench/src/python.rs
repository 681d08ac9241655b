//! The Python that runs the benchmarks' reference scripts (`bench nerf`, `unet`, `eval`):
//! `--python`, else `$GB_PYTHON`, else `python3` on `PATH`, checked to import the reference
//! packages before any timing starts. The pinned environment is made by
//! `tools/bench/make_venv.sh` (versions in `tools/bench/requirements.txt`).

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{anyhow, bail};

/// The script that creates the pinned reference environment.
pub const MAKE_VENV: &str = "tools/bench/make_venv.sh";

/// The environment variable naming the reference Python.
pub const PYTHON_ENV: &str = "GB_PYTHON";

/// What to do when the reference Python or its packages are missing.
fn advice() -> String {
    format!("create the reference environment with `bash {MAKE_VENV}` and set {PYTHON_ENV}=.venv-bench/bin/python (or pass --python)")
}

/// The reference Python (`explicit`, else `$GB_PYTHON`, else `python3` on `PATH`), once it
/// is known to import every module of `modules`; otherwise one line naming what is missing
/// and [`MAKE_VENV`].
pub fn reference_python(explicit: Option<&Path>, modules: &[&str]) -> anyhow::Result<PathBuf> {
    let python = pick_python(
        explicit,
        std::env::var_os(PYTHON_ENV),
        std::env::var_os("PATH"),
    )?;
    check_modules(&python, modules)?;
    Ok(python)
}

/// The lookup order of [`reference_python`]: `explicit`, `gb_python`, then the first
/// `python3` in the folders of `path`.
fn pick_python(
    explicit: Option<&Path>,
    gb_python: Option<OsString>,
    path: Option<OsString>,
) -> anyhow::Result<PathBuf> {
    if let Some(p) = explicit {
        return Ok(p.to_path_buf());
    }
    if let Some(p) = gb_python.filter(|p| !p.is_empty()) {
        return Ok(PathBuf::from(p));
    }
    path.iter()
        .flat_map(std::env::split_paths)
        .map(|dir| dir.join("python3"))
        .find(|p| p.is_file())
        .ok_or_else(|| {
            anyhow!(
                "no Python for the benchmark references ({PYTHON_ENV} unset, no python3 on PATH): {}",
                advice()
            )
        })
}

/// Fails with one line unless `python` runs and finds every module of `modules`.
fn check_modules(python: &Path, modules: &[&str]) -> anyhow::Result<()> {
    const PROBE: &str = "import importlib.util, sys; \
        print(' '.join(m for m in sys.argv[1:] if importlib.util.find_spec(m) is None))";
    let out = Command::new(python)
        .arg("-c")
        .arg(PROBE)
        .args(modules)
        .output()
        .map_err(|e| anyhow!("cannot run {} ({e}): {}", python.display(), advice()))?;
    if !out.status.success() {
        let why = String::from_utf8_lossy(&out.stderr);
        bail!(
            "{} failed ({}): {}",
            python.display(),
            why.lines().last().unwrap_or("no message").trim(),
            advice()
        );
    }
    let missing = String::from_utf8_lossy(&out.stdout).trim().to_string();
    if !missing.is_empty() {
        bail!(
            "{} lacks the benchmark reference packages ({missing}): {}",
            python.display(),
            advice()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup_order_is_flag_then_gb_python_then_path() {
        let dir = tempfile::tempdir().unwrap();
        let on_path = dir.path().join("python3");
        std::fs::write(&on_path, "").unwrap();
        let path = Some(std::env::join_paths([Path::new("/nonexistent"), dir.path()]).unwrap());
        let env = Some(OsString::from("/opt/venv/bin/python"));

        let flag = Path::new("/usr/bin/python3.12");
        assert_eq!(
            pick_python(Some(flag), env.clone(), path.clone()).unwrap(),
            flag
        );
        assert_eq!(
            pick_python(None, env, path.clone()).unwrap(),
            PathBuf::from("/opt/venv/bin/python")
        );
        assert_eq!(
            pick_python(None, Some(OsString::new()), path.clone()).unwrap(),
            on_path
        );
        assert_eq!(pick_python(None, None, path).unwrap(), on_path);

        let err = pick_python(None, None, Some(OsString::from("/nonexistent")))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(MAKE_VENV) && err.contains(PYTHON_ENV) && !err.contains('\n'),
            "{err}"
        );
    }

    #[test]
    fn a_python_that_cannot_run_names_the_script() {
        let err = check_modules(Path::new("/nonexistent/python3"), &["torch"])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("/nonexistent/python3") && err.contains(MAKE_VENV),
            "{err}"
        );
    }

    #[test]
    fn missing_packages_are_named_with_the_script() {
        let Ok(python) = pick_python(None, None, std::env::var_os("PATH")) else {
            eprintln!("no python3 on PATH: the package probe is not exercised");
            return;
        };
        check_modules(&python, &["json"]).unwrap();
        let err = check_modules(&python, &["json", "gb_no_such_module"])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("(gb_no_such_module)") && err.contains(MAKE_VENV),
            "{err}"
        );
    }
}
