//! Score distillation tests, one module per concern (a module of the crate's one test binary).

mod backends;
mod extremes;
mod finite_diff;
mod fixture;
mod formulas;
mod image;
mod mask;
mod oracle;
mod sd_prior;
mod support;
mod timesteps;
