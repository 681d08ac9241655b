//! Score distillation tests: one test binary, one module per concern.

mod backends;
mod extremes;
mod finite_diff;
mod fixture;
mod formulas;
mod mask;
mod oracle;
mod sd_prior;
mod support;
mod timesteps;
