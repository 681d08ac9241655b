//! The integration tests of this package, linked as one binary (`--test integration`):
//! each file of this folder is a module, so a change relinks one test binary, not one per
//! file. `cargo test --workspace --test integration --test help -- MODULE::` runs one file's
//! tests (`--test help` makes cargo build the `xtask` binary that the end-to-end tests run;
//! the filter is a substring, so `resume::` also runs `recipe_resume::`).

mod distill;
mod fp16_parity;
mod hub_loopback;
mod sd_image_common;
mod sd_image_inpaint;
mod sd_image_loading;
mod sd_image_parity;
mod sd_image_scheduler;
mod sd_text_common;
mod sd_text_loading;
mod sd_text_parity;
mod sd_text_tokenizer;
mod sd_text_unet_lora;
mod tiny_prior_parity;
