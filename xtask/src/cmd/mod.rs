//! One module per subcommand.

pub mod ablate;
pub mod capture;
pub mod devices;
pub mod distill_image;
pub mod eval;
pub mod export;
pub mod fill;
pub mod finetune;
pub mod fuzz;
pub mod inpaint;
pub mod inpaint_image;
pub mod job_resources;
pub mod parity;
pub mod scene;
pub mod scene_info;
