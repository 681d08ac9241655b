//! gb-finetune: RGB/normal datasets, random inpainting masks and LoRA fine-tuning of the geometric prior.
