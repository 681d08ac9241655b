//! One module per subcommand.

pub mod ablate;
pub mod bench;
pub mod bench_eval;
pub mod bench_gpu;
pub mod bench_nerf;
pub mod bench_pipeline;
pub mod bench_python;
pub mod bench_quality;
pub mod bench_unet;
pub mod devices;
pub mod distill_bench;
pub mod distill_image;
pub mod eval;
pub mod finetune;
pub mod fuzz;
pub mod inpaint;
pub mod inpaint_image;
pub mod parity;
pub mod parse;
pub mod scene;
pub mod scene_info;
