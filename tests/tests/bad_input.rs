//! Bad input through the CLI, one table of cases. Each case builds a small broken input in
//! its own folder (a copy of one tiny procedural scene, the committed priors and LoRA files,
//! or files corrupted here), runs one `cargo xtask` command and expects:
//!
//! - exit code 2 (not 0, not a panic's 101) and no `panicked` on stderr;
//! - no colour codes on stderr (it is a pipe here);
//! - stderr's last line is the only `error: ...` line, and it names the file, tensor, flag or
//!   field at fault;
//! - no result presented: no `metrics.json` or `report.html` anywhere in the case's folder.
//!
//! The `--resume` cases (no checkpoint, a checkpoint of another preset or method) are in
//! `inpaint_methods.rs`; loader-level cases in `crates/gb-nerf/tests/scene_bad_input.rs`.

use std::path::{Path, PathBuf};

use gb_tests::{path_str, small_stairs, workspace_root, xtask, FIXTURE_PRIOR};
use serde_json::{Map, Value};

/// Where a case builds its input.
struct Ctx {
    /// The case's own folder.
    dir: PathBuf,
    /// The template scene (never modified).
    template: PathBuf,
}

impl Ctx {
    /// A fresh copy of the template scene, `dir/scene`.
    fn scene(&self) -> PathBuf {
        let scene = self.dir.join("scene");
        copy_dir(&self.template, &scene);
        scene
    }

    /// `dir/NAME`.
    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// `inpaint --scene SCENE --out dir/out` with `extra` (one step, no orbit, so that a
    /// case the checks miss ends fast, and fails on its exit code).
    fn inpaint(&self, scene: &Path, extra: &[&str]) -> Vec<String> {
        let mut args = strings(&["inpaint", "--scene", path_str(scene)]);
        args.extend(strings(&["--out", path_str(&self.path("out"))]));
        args.extend(strings(&["--steps", "1", "--orbit-frames", "0"]));
        args.extend(strings(extra));
        args
    }

    /// `inpaint` with the no-prior method, for the scene and config cases.
    fn inpaint_none(&self, scene: &Path, extra: &[&str]) -> Vec<String> {
        let mut e = vec!["--method", "none"];
        e.extend_from_slice(extra);
        self.inpaint(scene, &e)
    }

    /// A copy of the committed tiny SD-inpainting fixture prior, `dir/prior`.
    fn prior_copy(&self) -> PathBuf {
        let prior = self.path("prior");
        copy_dir(&workspace_root().join(FIXTURE_PRIOR), &prior);
        prior
    }
}

/// What a case runs and what its error line must name.
struct Run {
    args: Vec<String>,
    expect: Vec<String>,
}

fn run(args: Vec<String>, expect: &[&str]) -> Run {
    Run {
        args,
        expect: strings(expect),
    }
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let p = e.unwrap().path();
        let to = dst.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &to);
        } else {
            std::fs::copy(&p, &to).unwrap();
        }
    }
}

/// Every file named `name` under `dir`.
fn find_named(dir: &Path, name: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(find_named(&p, name));
        } else if p.file_name().is_some_and(|n| n == name) {
            out.push(p);
        }
    }
    out
}

/// The `.png` files directly in `dir`, sorted.
fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    v.sort();
    v
}

/// Sets element `index` of a little-endian float `.npy` file (`<f4` or `<f8`, format 1.0).
fn npy_set(path: &Path, index: usize, value: f64) {
    let mut b = std::fs::read(path).unwrap();
    assert_eq!(&b[..6], b"\x93NUMPY", "{}", path.display());
    let header_len = u16::from_le_bytes([b[8], b[9]]) as usize;
    let header = String::from_utf8_lossy(&b[10..10 + header_len]).to_string();
    let start = 10 + header_len;
    if header.contains("'<f8'") {
        b[start + 8 * index..start + 8 * index + 8].copy_from_slice(&value.to_le_bytes());
    } else {
        assert!(header.contains("'<f4'"), "{header}");
        let v = value as f32;
        b[start + 4 * index..start + 4 * index + 4].copy_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, b).unwrap();
}

/// A safetensors file split into its header and its data.
struct Safetensors {
    header: Map<String, Value>,
    data: Vec<u8>,
}

impl Safetensors {
    fn read(path: &Path) -> Self {
        let b = std::fs::read(path).unwrap();
        let n = u64::from_le_bytes(b[..8].try_into().unwrap()) as usize;
        let header: Value = serde_json::from_slice(&b[8..8 + n]).unwrap();
        Self {
            header: header.as_object().unwrap().clone(),
            data: b[8 + n..].to_vec(),
        }
    }

    /// Writes the file; the data stays as it is (only header edits are made here).
    fn write(&self, path: &Path) {
        let mut h = serde_json::to_vec(&self.header).unwrap();
        while !h.len().is_multiple_of(8) {
            h.push(b' ');
        }
        let mut b = (h.len() as u64).to_le_bytes().to_vec();
        b.extend_from_slice(&h);
        b.extend_from_slice(&self.data);
        std::fs::write(path, b).unwrap();
    }

    /// The tensor names in data order.
    fn names_by_offset(&self) -> Vec<String> {
        let mut v: Vec<(u64, String)> = self
            .header
            .iter()
            .filter(|(k, _)| *k != "__metadata__")
            .map(|(k, t)| (t["data_offsets"][0].as_u64().unwrap(), k.clone()))
            .collect();
        v.sort();
        v.into_iter().map(|(_, k)| k).collect()
    }

    fn shape(&self, name: &str) -> Vec<u64> {
        self.header[name]["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d.as_u64().unwrap())
            .collect()
    }

    fn set_shape(&mut self, name: &str, shape: &[u64]) {
        let before: u64 = self.shape(name).iter().product();
        assert_eq!(before, shape.iter().product::<u64>(), "same element count");
        self.header[name]["shape"] = serde_json::json!(shape);
    }

    /// Relabels a float tensor as the integer dtype of the same width (the bytes stay).
    fn set_integer_dtype(&mut self, name: &str) {
        let int = match self.header[name]["dtype"].as_str().unwrap() {
            "F32" => "I32",
            "F16" | "BF16" => "I16",
            "F64" => "I64",
            other => panic!("{name}: dtype {other} is not a float"),
        };
        self.header[name]["dtype"] = int.into();
    }

    /// Writes the file cut inside the data of its last tensor; returns that tensor's name.
    fn write_truncated(&self, path: &Path) -> String {
        self.write(path);
        let last = self.names_by_offset().pop().unwrap();
        let begin = self.header[&last]["data_offsets"][0].as_u64().unwrap();
        let len = std::fs::metadata(path).unwrap().len();
        let keep = len - self.data.len() as u64 + begin + 2;
        let f = std::fs::OpenOptions::new().write(true).open(path).unwrap();
        f.set_len(keep).unwrap();
        last
    }
}

/// The built-in prior's LoRA file.
fn tiny_lora() -> PathBuf {
    gb_core::tiny_prior_dir().join("pytorch_lora_weights.safetensors")
}

/// Down / up suffixes of the LoRA key formats.
const LORA_PAIRS: [(&str, &str); 3] = [
    (".lora_A.weight", ".lora_B.weight"),
    (".lora.down.weight", ".lora.up.weight"),
    (".lora_down.weight", ".lora_up.weight"),
];

/// A module of a LoRA file with 2-D factors, `down [r, in]` and `up [out, r]` with `in` and
/// `out` even: `(module stem, down key, up key)`.
fn linear_lora_module(st: &Safetensors) -> (String, String, String) {
    for name in st.names_by_offset() {
        for (down, up) in LORA_PAIRS {
            let Some(stem) = name.strip_suffix(down) else {
                continue;
            };
            let up_key = format!("{stem}{up}");
            if !st.header.contains_key(&up_key) {
                continue;
            }
            let (d, u) = (st.shape(&name), st.shape(&up_key));
            if d.len() == 2 && u.len() == 2 && d[1] % 2 == 0 && u[0] % 2 == 0 {
                return (stem.to_string(), name.clone(), up_key);
            }
        }
    }
    panic!("no 2-D LoRA module in the tiny prior's LoRA file");
}

/// A minimal pickle (protocol 2, an empty dict) and the start of `torch.save`'s zip format.
const PICKLE: &[u8] = b"\x80\x02}q\x00.";
const TORCH_ZIP: &[u8] = b"PK\x03\x04\x14\x00\x00\x00\x08\x00archive/data.pkl";

/// The fixture prior's U-Net weights.
const UNET_FILE: &str = "unet/diffusion_pytorch_model.safetensors";

type Setup = fn(&Ctx) -> Run;

/// A named case (the closure coerces to a [`Setup`] here).
fn case(name: &'static str, setup: Setup) -> (&'static str, Setup) {
    (name, setup)
}

/// Every case: its name and how it builds its input.
fn cases() -> Vec<(&'static str, Setup)> {
    vec![
        case("inpaint --steps 0", |c| {
            let s = c.scene();
            let mut args = c.inpaint_none(&s, &[]);
            let i = args.iter().position(|a| a == "--steps").unwrap();
            args[i + 1] = "0".into();
            run(args, &["--steps", "at least 1"])
        }),
        case("a pickled .ckpt as --prior", |c| {
            let ckpt = c.path("model.ckpt");
            std::fs::write(&ckpt, PICKLE).unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--prior", path_str(&ckpt)]),
                &["model.ckpt", "pickle", "safetensors"],
            )
        }),
        case("a torch .bin as --prior", |c| {
            let bin = c.path("model.bin");
            std::fs::write(&bin, TORCH_ZIP).unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--prior", path_str(&bin)]),
                &["model.bin", "pickle", "safetensors"],
            )
        }),
        case("a prior folder with .bin weights only", |c| {
            let prior = c.path("prior");
            let tiny = gb_core::tiny_prior_dir();
            std::fs::create_dir_all(prior.join("unet")).unwrap();
            std::fs::copy(
                tiny.join("model_index.json"),
                prior.join("model_index.json"),
            )
            .unwrap();
            std::fs::copy(
                tiny.join("unet/config.json"),
                prior.join("unet/config.json"),
            )
            .unwrap();
            std::fs::write(prior.join("unet/diffusion_pytorch_model.bin"), TORCH_ZIP).unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--prior", path_str(&prior)]),
                &["diffusion_pytorch_model.bin", "`unet`", "safetensors"],
            )
        }),
        case("a pickled LoRA file", |c| {
            let lora = c.path("lora.bin");
            std::fs::write(&lora, PICKLE).unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--lora", path_str(&lora)]),
                &["lora.bin", "pickle", "safetensors"],
            )
        }),
        case("a LoRA tensor of an integer dtype", |c| {
            let mut st = Safetensors::read(&tiny_lora());
            let (_, down, _) = linear_lora_module(&st);
            st.set_integer_dtype(&down);
            let lora = c.path("int_lora.safetensors");
            st.write(&lora);
            let s = c.scene();
            let args = c.inpaint(&s, &["--lora", path_str(&lora)]);
            Run {
                args,
                expect: vec!["int_lora.safetensors".into(), down, "dtype".into()],
            }
        }),
        case("LoRA factors of the wrong shape", |c| {
            let mut st = Safetensors::read(&tiny_lora());
            let (stem, down, up) = linear_lora_module(&st);
            let (d, u) = (st.shape(&down), st.shape(&up));
            // twice the rank, half the input and output width: consistent, but not the
            // weight's shape
            st.set_shape(&down, &[d[0] * 2, d[1] / 2]);
            st.set_shape(&up, &[u[0] / 2, u[1] * 2]);
            let lora = c.path("reshaped_lora.safetensors");
            st.write(&lora);
            let s = c.scene();
            let args = c.inpaint(&s, &["--lora", path_str(&lora)]);
            Run {
                args,
                expect: vec!["reshaped_lora.safetensors".into(), stem, "shape".into()],
            }
        }),
        case("a truncated LoRA file", |c| {
            let st = Safetensors::read(&tiny_lora());
            let lora = c.path("cut_lora.safetensors");
            let last = st.write_truncated(&lora);
            let s = c.scene();
            let args = c.inpaint(&s, &["--lora", path_str(&lora)]);
            Run {
                args,
                expect: vec!["cut_lora.safetensors".into(), last, "past the end".into()],
            }
        }),
        case("U-Net weights of the wrong shape", |c| {
            let prior = c.prior_copy();
            let file = prior.join(UNET_FILE);
            let mut st = Safetensors::read(&file);
            let k = st.shape("conv_in.weight");
            st.set_shape("conv_in.weight", &[k[0], k[1], k[2] * k[3], 1]);
            st.write(&file);
            let s = c.scene();
            run(
                c.inpaint(&s, &["--method", "bsd", "--prior", path_str(&prior)]),
                &[UNET_FILE, "conv_in.weight", "shape"],
            )
        }),
        case("U-Net weights of an integer dtype", |c| {
            let prior = c.prior_copy();
            let file = prior.join(UNET_FILE);
            let mut st = Safetensors::read(&file);
            st.set_integer_dtype("conv_in.weight");
            st.write(&file);
            let s = c.scene();
            run(
                c.inpaint(&s, &["--method", "bsd", "--prior", path_str(&prior)]),
                &[UNET_FILE, "conv_in.weight", "dtype"],
            )
        }),
        case("truncated U-Net weights", |c| {
            let prior = c.prior_copy();
            let file = prior.join(UNET_FILE);
            let last = Safetensors::read(&file).write_truncated(&file);
            let s = c.scene();
            let args = c.inpaint(&s, &["--method", "bsd", "--prior", path_str(&prior)]);
            Run {
                args,
                expect: vec![UNET_FILE.into(), last, "past the end".into()],
            }
        }),
        case("a mask with grey levels", |c| {
            let s = c.scene();
            let mask = s.join("images_1/label/view_002.png");
            let (w, h, mut v) = gb_core::read_gray(&mask).unwrap();
            v[0] = 1.0;
            v[1..5].fill(0.5);
            gb_core::write_gray_png(&mask, w, h, &v).unwrap();
            run(c.inpaint_none(&s, &[]), &["view_002.png", "not binary"])
        }),
        case("images of different sizes", |c| {
            let s = c.scene();
            let img = s.join("images_1/view_004.png");
            gb_core::write_rgb_png(&img, &gb_core::RgbImage::filled(20, 18, [0.5; 3])).unwrap();
            run(c.inpaint_none(&s, &[]), &["view_004.png", "20x18", "24x18"])
        }),
        case("infinity in poses_bounds.npy", |c| {
            let s = c.scene();
            npy_set(&s.join("poses_bounds.npy"), 17 * 2 + 3, f64::INFINITY);
            run(
                c.inpaint_none(&s, &[]),
                &["poses_bounds.npy", "inf", "row 2, column 3"],
            )
        }),
        case("NaN in a depth map", |c| {
            let s = c.scene();
            npy_set(&s.join("depth_1/view_003.npy"), 24 * 2 + 5, f64::NAN);
            run(
                c.inpaint_none(&s, &[]),
                &["view_003.npy", "NaN", "pixel (5, 2)"],
            )
        }),
        case("infinity in a depth map", |c| {
            let s = c.scene();
            npy_set(&s.join("depth_1/view_001.npy"), 0, f64::NEG_INFINITY);
            run(c.inpaint_none(&s, &[]), &["view_001.npy", "-inf"])
        }),
        case("an empty mask in every view", |c| {
            let s = c.scene();
            for m in pngs(&s.join("images_1/label")) {
                gb_core::write_gray_png(&m, 24, 18, &[0.0; 24 * 18]).unwrap();
            }
            run(
                c.inpaint_none(&s, &[]),
                &["scene 'scene'", "no training view with an object mask"],
            )
        }),
        case("a mask covering a whole image", |c| {
            let s = c.scene();
            let m = s.join("images_1/label/view_003.png");
            gb_core::write_gray_png(&m, 24, 18, &[1.0; 24 * 18]).unwrap();
            run(
                c.inpaint_none(&s, &[]),
                &["view_003", "covers the whole 24x18 image"],
            )
        }),
        case("transforms.json naming a missing frame", |c| {
            let s = c.path("blender");
            std::fs::create_dir_all(s.join("frames")).unwrap();
            let img = gb_core::RgbImage::filled(16, 12, [0.3; 3]);
            gb_core::write_rgb_png(&s.join("frames/a.png"), &img).unwrap();
            let eye = [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 4.0],
            ];
            let json = serde_json::json!({
                "camera_angle_x": 0.7,
                "frames": [
                    {"file_path": "./frames/a", "transform_matrix": eye},
                    {"file_path": "./frames/b", "transform_matrix": eye},
                ],
            });
            std::fs::write(s.join("transforms.json"), json.to_string()).unwrap();
            run(
                c.inpaint_none(&s, &[]),
                &["transforms.json", "frame 1", "b.png", "does not exist"],
            )
        }),
        case("a captions file that is not UTF-8", |c| {
            let scan = c.path("diode/train/indoors/scene_00001/scan_00001");
            std::fs::create_dir_all(&scan).unwrap();
            let img = gb_core::RgbImage::filled(16, 12, [0.3; 3]);
            gb_core::write_rgb_png(&scan.join("00001_00001_indoors_000_010.png"), &img).unwrap();
            let captions = c.path("captions.jsonl");
            std::fs::write(
                &captions,
                b"{\"image\": \"00001_00001_indoors_000_010.png\", \"caption\": \"caf\xe9\"}\n",
            )
            .unwrap();
            let args = strings(&[
                "finetune",
                "--diode",
                path_str(&c.path("diode")),
                "--base",
                "tiny",
                "--captions",
                path_str(&captions),
                "--steps",
                "1",
                "--out",
                path_str(&c.path("out")),
            ]);
            run(args, &["captions.jsonl", "line 1", "not UTF-8"])
        }),
        case("--out under a regular file", |c| {
            let file = c.path("file.txt");
            std::fs::write(&file, b"x").unwrap();
            let s = c.scene();
            let mut args = c.inpaint_none(&s, &[]);
            let i = args.iter().position(|a| a == "--out").unwrap();
            args[i + 1] = path_str(&file.join("run")).into();
            run(args, &["--out", "file.txt", "not a folder"])
        }),
        case("an unknown method", |c| {
            let s = c.scene();
            run(
                c.inpaint(&s, &["--method", "nerf-magic"]),
                &["unknown method 'nerf-magic'", "gb-nerf"],
            )
        }),
        case("an unknown preset", |c| {
            let s = c.scene();
            run(
                c.inpaint_none(&s, &["--preset", "turbo"]),
                &["unknown preset 'turbo'", "fast"],
            )
        }),
        case("a method TOML with an unknown field", |c| {
            let none = std::fs::read_to_string(workspace_root().join("configs/methods/none.toml"))
                .unwrap();
            let m = c.path("typo.toml");
            std::fs::write(&m, format!("lambda_rgbb = 1.0\n{none}")).unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--method", path_str(&m)]),
                &["typo.toml", "unknown field `lambda_rgbb`", "line 1"],
            )
        }),
        case("a guidance weight that is neither a number nor auto", |c| {
            let unseen = std::fs::read_to_string(
                workspace_root().join("configs/methods/gb-nerf-unseen.toml"),
            )
            .unwrap()
            .replace("lambda_rgb = 1e-5", "lambda_rgb = \"big\"");
            let m = c.path("weight.toml");
            std::fs::write(&m, unseen).unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--method", path_str(&m)]),
                &["weight.toml", "expected a number or \"auto\"", "lambda_rgb"],
            )
        }),
        case("an [oracle] clean folder that does not exist", |c| {
            let unseen = std::fs::read_to_string(
                workspace_root().join("configs/methods/gb-nerf-unseen.toml"),
            )
            .unwrap();
            let m = c.path("oracle.toml");
            let missing = c.path("no-such-clean");
            std::fs::write(
                &m,
                format!("{unseen}\n[oracle]\nclean = \"{}\"\n", path_str(&missing)),
            )
            .unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--method", path_str(&m)]),
                &["[oracle] clean", "no-such-clean", "not a folder"],
            )
        }),
        case("a [personalize] object_free image of the wrong size", |c| {
            let unseen = std::fs::read_to_string(
                workspace_root().join("configs/methods/gb-nerf-unseen.toml"),
            )
            .unwrap();
            let s = c.scene();
            let clean = c.path("clean");
            std::fs::create_dir_all(&clean).unwrap();
            let small = gb_core::RgbImage::filled(3, 2, [0.5; 3]);
            for view in pngs(&s.join("images_1")) {
                gb_core::write_rgb_png(&clean.join(view.file_name().unwrap()), &small).unwrap();
            }
            let m = c.path("personal.toml");
            std::fs::write(
                &m,
                format!(
                    "{unseen}\n[personalize]\nsteps = 1\nobject_free = \"{}\"\n",
                    path_str(&clean)
                ),
            )
            .unwrap();
            run(
                c.inpaint(&s, &["--method", path_str(&m)]),
                &["[personalize] object_free", "the image is 3x2"],
            )
        }),
        case("a method TOML with a mistyped field", |c| {
            let none = std::fs::read_to_string(workspace_root().join("configs/methods/none.toml"))
                .unwrap();
            let typed = none.replace("max_consecutive_nan = 10", "max_consecutive_nan = \"ten\"");
            assert_ne!(typed, none);
            let m = c.path("typed.toml");
            std::fs::write(&m, typed).unwrap();
            let s = c.scene();
            run(
                c.inpaint(&s, &["--method", path_str(&m)]),
                &["typed.toml", "max_consecutive_nan", "invalid type"],
            )
        }),
        case("a preset TOML with a negative learning rate", |c| {
            let p = c.path("neg_lr.toml");
            std::fs::write(&p, fast_preset().replace("lr = 1e-2", "lr = -1e-2")).unwrap();
            let s = c.scene();
            run(
                c.inpaint_none(&s, &["--preset", path_str(&p)]),
                &["neg_lr.toml", "train.lr"],
            )
        }),
        case("a preset TOML with zero samples per ray", |c| {
            let p = c.path("no_samples.toml");
            let text = fast_preset().replace("samples_per_ray = 40", "samples_per_ray = 0");
            std::fs::write(&p, text).unwrap();
            let s = c.scene();
            run(
                c.inpaint_none(&s, &["--preset", path_str(&p)]),
                &["no_samples.toml", "sampler.samples_per_ray"],
            )
        }),
        case("--device with an unknown value", |c| {
            let s = c.scene();
            run(
                c.inpaint_none(&s, &["--device", "cuda"]),
                &["--device", "'cuda'", "ndarray, flex, wgpu"],
            )
        }),
        case("a missing scene folder", |c| {
            let s = c.path("no_such_scene");
            run(c.inpaint_none(&s, &[]), &["no_such_scene", "not a folder"])
        }),
        case("a scene folder without images", |c| {
            let s = c.scene();
            for p in pngs(&s.join("images_1")) {
                std::fs::remove_file(p).unwrap();
            }
            run(
                c.inpaint_none(&s, &[]),
                &["images_1", "0 images but 5 poses"],
            )
        }),
        case("eval with folders of different lengths", |c| {
            let (pred, gt) = (c.path("pred"), c.path("gt"));
            let img = gb_core::RgbImage::filled(8, 8, [0.5; 3]);
            for (dir, n) in [(&pred, 2), (&gt, 1)] {
                std::fs::create_dir_all(dir).unwrap();
                for i in 0..n {
                    gb_core::write_rgb_png(&dir.join(format!("v{i}.png")), &img).unwrap();
                }
            }
            let args = strings(&[
                "eval",
                "--pred",
                path_str(&pred),
                "--gt",
                path_str(&gt),
                "--metrics",
                "psnr",
                "--json",
                path_str(&c.path("out/metrics.json")),
            ]);
            run(args, &["pred", "gt", "holds 2 files", "holds 1"])
        }),
        case("eval with images of different sizes", |c| {
            let (pred, gt) = (c.path("pred"), c.path("gt"));
            for (dir, w) in [(&pred, 8), (&gt, 10)] {
                std::fs::create_dir_all(dir).unwrap();
                let img = gb_core::RgbImage::filled(w, 8, [0.5; 3]);
                gb_core::write_rgb_png(&dir.join("v0.png"), &img).unwrap();
            }
            let args = strings(&[
                "eval",
                "--pred",
                path_str(&pred),
                "--gt",
                path_str(&gt),
                "--metrics",
                "psnr",
                "--json",
                path_str(&c.path("out/metrics.json")),
            ]);
            run(args, &["v0.png", "8x8", "10x8"])
        }),
        case("scene --width 0", |c| {
            let args = strings(&[
                "scene",
                "--name",
                "stairs",
                "--width",
                "0",
                "--out",
                path_str(&c.path("out")),
            ]);
            run(args, &["--width", "between 8 and 8192"])
        }),
        case("finetune --diode with a missing folder", |c| {
            let args = strings(&[
                "finetune",
                "--diode",
                path_str(&c.path("no_diode")),
                "--base",
                "tiny",
                "--out",
                path_str(&c.path("out")),
            ]);
            run(args, &["no_diode", "DIODE root folder"])
        }),
        case(
            "finetune --data-parallel mpi of the tiny prior's recipe",
            |c| {
                let args = strings(&[
                    "finetune",
                    "--synthetic",
                    "--from-scratch",
                    "--data-parallel",
                    "mpi",
                    "--out",
                    path_str(&c.path("out")),
                ]);
                run(args, &["--data-parallel mpi", "not --from-scratch"])
            },
        ),
        case("--lora pointing at a missing file", |c| {
            let s = c.scene();
            let lora = c.path("no_lora.safetensors");
            run(
                c.inpaint(&s, &["--lora", path_str(&lora)]),
                &["no_lora.safetensors", "no such file"],
            )
        }),
        case("--lora with a method without guidance", |c| {
            let s = c.scene();
            let lora = tiny_lora();
            run(
                c.inpaint_none(&s, &["--lora", path_str(&lora)]),
                &["--lora", "method 'none' has no guidance"],
            )
        }),
        case("--baseline that is not a folder", |c| {
            let file = c.path("baseline.png");
            std::fs::write(&file, b"x").unwrap();
            let s = c.scene();
            run(
                c.inpaint_none(&s, &["--baseline", path_str(&file)]),
                &["--baseline", "baseline.png", "not a folder"],
            )
        }),
        case("export --run of a folder that is no run", |c| {
            let s = c.scene();
            run(
                strings(&["export", "--run", path_str(&s)]),
                &["--run", "config.toml is missing"],
            )
        }),
        case("a missing prior folder", |c| {
            let s = c.scene();
            let prior = c.path("no_prior");
            run(
                c.inpaint(&s, &["--method", "bsd", "--prior", path_str(&prior)]),
                &["no_prior", "no such folder"],
            )
        }),
    ]
}

/// The `fast` preset as text.
fn fast_preset() -> String {
    std::fs::read_to_string(workspace_root().join("configs/presets/fast.toml")).unwrap()
}

/// Runs one case; returns what is wrong with its outcome, if anything.
fn check_case(name: &str, setup: Setup, template: &Path, root: &Path, i: usize) -> Option<String> {
    let ctx = Ctx {
        dir: root.join(format!("case_{i:02}")),
        template: template.to_path_buf(),
    };
    std::fs::create_dir_all(&ctx.dir).unwrap();
    let r = setup(&ctx);
    let args: Vec<&str> = r.args.iter().map(String::as_str).collect();
    let out = xtask(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    let mut problems = Vec::new();
    if out.status.code() != Some(2) {
        problems.push(format!("exit code {:?}, expected 2", out.status.code()));
    }
    if err.contains("panicked") {
        problems.push("a panic".into());
    }
    if err.contains("\x1b[") {
        problems.push("colour codes on a pipe".into());
    }
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    let error_lines = lines.iter().filter(|l| l.starts_with("error:")).count();
    match lines.last() {
        Some(last) if last.starts_with("error: ") && error_lines == 1 => {
            println!("{name}\n    {last}");
            if last.contains("   ") {
                problems.push("a run of spaces in the error line (a broken continuation?)".into());
            }
            for e in &r.expect {
                if !last.contains(e.as_str()) {
                    problems.push(format!("the error line does not name `{e}`"));
                }
            }
        }
        _ => problems.push(format!(
            "the last line is not the only `error: ...` line ({error_lines} error lines)"
        )),
    }
    for result in ["metrics.json", "report.html"] {
        if let Some(p) = find_named(&ctx.dir, result).first() {
            problems.push(format!("a result was written: {}", p.display()));
        }
    }
    (!problems.is_empty()).then(|| {
        format!(
            "case `{name}` ({}): {}\n--- stderr:\n{err}",
            r.args.join(" "),
            problems.join("; ")
        )
    })
}

#[test]
fn every_bad_input_is_one_clear_error_line_with_exit_code_2() {
    let root = tempfile::tempdir().unwrap();
    let template = small_stairs(root.path(), 24, 18, 0);
    let cases = cases();
    assert!(cases.len() >= 30, "{} cases", cases.len());
    // `GB_BAD_INPUT_ONLY=TEXT` runs the cases whose name holds TEXT (while writing one)
    let only = std::env::var("GB_BAD_INPUT_ONLY").unwrap_or_default();
    let failures: Vec<String> = cases
        .iter()
        .enumerate()
        .filter(|(_, (name, _))| name.contains(only.as_str()))
        .filter_map(|(i, (name, setup))| check_case(name, *setup, &template, root.path(), i))
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
}
