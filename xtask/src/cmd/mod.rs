//! One module per subcommand.

pub mod bench;
pub mod bench_eval;
pub mod bench_nerf;
pub mod devices;
pub mod eval;
pub mod inpaint;
pub mod scene;
pub mod scene_info;
