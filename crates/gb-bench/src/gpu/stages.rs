//! The stages of `bench gpu`, each of which may fail on a GPU that has never run the code
//! (SPIR-V refused, out of memory, a driver panic): a failed stage is recorded with its
//! error and the rest still run; a stage that would start after the time budget is spent is
//! skipped and says so; the report is rewritten (atomically) after every stage, so that a
//! command killed at its time limit still leaves what it measured.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use serde_json::{json, Map, Value};

/// A report written stage by stage (module docs).
pub(super) struct StagedReport {
    path: PathBuf,
    doc: Map<String, Value>,
    stages: Map<String, Value>,
    started: Instant,
    budget: Duration,
}

impl StagedReport {
    /// A report at `path` that starts with the fields of `head` (an object), with `budget`
    /// for all its stages together.
    pub(super) fn new(path: PathBuf, head: Value, budget: Duration) -> Self {
        let mut doc = match head {
            Value::Object(m) => m,
            other => Map::from_iter([("head".to_string(), other)]),
        };
        doc.insert("budget_s".into(), json!(budget.as_secs_f64()));
        Self {
            path,
            doc,
            stages: Map::new(),
            started: Instant::now(),
            budget,
        }
    }

    /// Runs `f` as the stage `name`, unless the budget is spent. Its value goes under
    /// `stages.<name>` with the seconds it took (`stage_s`); a failure or a panic becomes
    /// `{"error": ...}` there, a skipped stage `{"skipped": ...}`. Returns the value of a
    /// stage that succeeded. The report is written after the stage.
    pub(super) fn stage(
        &mut self,
        name: &str,
        f: impl FnOnce() -> anyhow::Result<Value>,
    ) -> Option<Value> {
        let elapsed = self.started.elapsed();
        let (entry, value) = if elapsed >= self.budget {
            let why = format!(
                "the time budget of {:.0} s was spent ({:.0} s elapsed)",
                self.budget.as_secs_f64(),
                elapsed.as_secs_f64()
            );
            tracing::warn!(stage = name, "skipped: {why}");
            (json!({ "skipped": why }), None)
        } else {
            tracing::info!(stage = name, "bench gpu stage");
            // a process that ends inside the stage (killed at its time limit, aborted by a
            // driver) leaves this behind
            self.record(
                name,
                json!({ "error": "did not finish: the process ended inside this stage" }),
            );
            let s = Instant::now();
            let outcome = catch_unwind(AssertUnwindSafe(f));
            let seconds = s.elapsed().as_secs_f64();
            match outcome {
                Ok(Ok(v)) => {
                    let mut entry = match v.clone() {
                        Value::Object(m) => m,
                        other => Map::from_iter([("value".to_string(), other)]),
                    };
                    entry.insert("stage_s".into(), json!(seconds));
                    (Value::Object(entry), Some(v))
                }
                Ok(Err(e)) => {
                    tracing::error!(stage = name, "failed: {e:#}");
                    (
                        json!({ "error": format!("{e:#}"), "stage_s": seconds }),
                        None,
                    )
                }
                Err(panic) => {
                    let msg = panic_message(&*panic);
                    tracing::error!(stage = name, "panicked: {msg}");
                    (
                        json!({ "error": format!("panic: {msg}"), "stage_s": seconds }),
                        None,
                    )
                }
            }
        };
        self.record(name, entry);
        value
    }

    /// Sets the entry of stage `name` and writes the report.
    fn record(&mut self, name: &str, entry: Value) {
        self.stages.insert(name.to_string(), entry);
        if let Err(e) = self.write() {
            tracing::warn!("{e:#}");
        }
    }

    /// Sets a top-level field.
    pub(super) fn set(&mut self, key: &str, value: Value) {
        self.doc.insert(key.to_string(), value);
    }

    /// Records the total wall time and writes the report a last time, printing it.
    pub(super) fn finish(mut self) -> anyhow::Result<PathBuf> {
        self.set("wall_s", json!(self.started.elapsed().as_secs_f64()));
        let mut failed: Vec<&String> = self
            .stages
            .iter()
            .filter(|(_, v)| v.get("error").is_some() || v.get("skipped").is_some())
            .map(|(k, _)| k)
            .collect();
        failed.sort();
        let failed = json!(failed);
        self.set("stages_not_measured", failed);
        let dir = self.path.parent().unwrap_or(Path::new("."));
        let file = self
            .path
            .file_name()
            .context("--out names no file")?
            .to_string_lossy()
            .into_owned();
        crate::write_report(dir, &file, &self.document())
    }

    /// The report as written: the fields, and the stages under `stages`.
    fn document(&self) -> Value {
        let mut doc = self.doc.clone();
        doc.insert("stages".into(), Value::Object(self.stages.clone()));
        Value::Object(doc)
    }

    fn write(&self) -> anyhow::Result<()> {
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create", dir.display()))?;
        }
        let text = serde_json::to_string_pretty(&self.document())? + "\n";
        gb_core::write_atomic(&self.path, text.as_bytes())
            .with_context(|| format!("{}: cannot write", self.path.display()))
    }
}

/// The message of a caught panic.
fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "a panic without a message".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(path: &Path) -> Value {
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
    }

    #[test]
    fn a_stage_the_process_dies_in_is_on_file_as_unfinished() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gpu.json");
        let mut report = StagedReport::new(path.clone(), json!({}), Duration::from_secs(60));
        let seen = std::cell::RefCell::new(Value::Null);
        report.stage("unet", || {
            *seen.borrow_mut() = read(&path);
            Ok(json!({}))
        });
        let during = seen.into_inner();
        let note = during["stages"]["unet"]["error"].as_str().unwrap();
        assert!(note.contains("did not finish"), "{note}");
        assert!(read(&path)["stages"]["unet"]["error"].is_null());
    }

    #[test]
    fn a_failing_or_panicking_stage_is_recorded_and_the_next_still_runs() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gpu.json");
        let head = json!({ "benchmark": "gpu" });
        let mut report = StagedReport::new(path.clone(), head, Duration::from_secs(600));
        let first = report.stage("unet", || Ok(json!({ "steady_s": 0.5 })));
        assert_eq!(first, Some(json!({ "steady_s": 0.5 })));
        // written after the first stage already
        assert_eq!(read(&path)["stages"]["unet"]["steady_s"], json!(0.5));
        let failed = report.stage("vae", || anyhow::bail!("SPIR-V refused"));
        assert_eq!(failed, None);
        let panicked = report.stage("nerf", || panic!("out of memory"));
        assert_eq!(panicked, None);
        let last = report.stage("scalar", || Ok(json!(3.0)));
        assert_eq!(last, Some(json!(3.0)));
        let out = report.finish().unwrap();
        let doc = read(&out);
        assert_eq!(doc["benchmark"], json!("gpu"));
        assert_eq!(doc["stages"]["vae"]["error"], json!("SPIR-V refused"));
        assert_eq!(
            doc["stages"]["nerf"]["error"],
            json!("panic: out of memory")
        );
        assert_eq!(doc["stages"]["scalar"]["value"], json!(3.0));
        assert!(doc["stages"]["scalar"]["stage_s"].as_f64().unwrap() >= 0.0);
        assert_eq!(doc["stages_not_measured"], json!(["nerf", "vae"]));
        assert!(doc["wall_s"].as_f64().unwrap() >= 0.0);
    }

    #[test]
    fn a_stage_after_the_budget_is_skipped_without_running() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("gpu.json");
        let mut report = StagedReport::new(path.clone(), json!({}), Duration::ZERO);
        assert!(!path.exists());
        let mut ran = false;
        let v = report.stage("unet", || {
            ran = true;
            Ok(json!(1.0))
        });
        assert!(!ran);
        assert_eq!(v, None);
        let skipped = read(&path)["stages"]["unet"]["skipped"].clone();
        assert!(
            skipped.as_str().unwrap().contains("time budget of 0 s"),
            "{skipped}"
        );
    }
}
