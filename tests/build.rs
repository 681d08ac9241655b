//! Marks the tests that need the shared test data as ignored when it is missing: the check
//! lives in the gb-testdata crate (see its docs). Marks the test
//! of the Slurm array job (`grid_slurm.rs`) as ignored when the build sees no Slurm to test
//! against: neither `SLURM_CONF` nor `GB_TEST_SLURM` (which `.ci/run` sets) is set; and the
//! capture test (`capture.rs`) when no `colmap` runs and `GB_TEST_COLMAP` is not set (`.ci/run`
//! installs COLMAP and sets it, so there a missing COLMAP fails); and the data-parallel
//! launch test (`mpi_launch.rs`) unless `GB_TEST_MPI` is set.

fn main() {
    gb_testdata::emit_build_script_cfg();
    println!("cargo::rustc-check-cfg=cfg(gb_no_slurm)");
    println!("cargo::rerun-if-env-changed=SLURM_CONF");
    println!("cargo::rerun-if-env-changed=GB_TEST_SLURM");
    if std::env::var_os("SLURM_CONF").is_none() && std::env::var_os("GB_TEST_SLURM").is_none() {
        println!("cargo::rustc-cfg=gb_no_slurm");
    }
    // the data-parallel launch test (`mpi_launch.rs`) needs gb-nerf built with the `mpi`
    // feature, which only `.ci/run`'s second command (GB_TEST_MPI=1) builds
    println!("cargo::rustc-check-cfg=cfg(gb_no_mpi)");
    println!("cargo::rerun-if-env-changed=GB_TEST_MPI");
    if std::env::var_os("GB_TEST_MPI").is_none() {
        println!("cargo::rustc-cfg=gb_no_mpi");
    }
    println!("cargo::rustc-check-cfg=cfg(gb_no_colmap)");
    println!("cargo::rerun-if-env-changed=PATH");
    println!("cargo::rerun-if-env-changed=GB_TEST_COLMAP");
    let colmap = std::env::var_os("GB_TEST_COLMAP").is_some()
        || std::process::Command::new("colmap")
            .arg("help")
            .output()
            .is_ok_and(|o| o.status.success());
    if !colmap {
        println!("cargo::rustc-cfg=gb_no_colmap");
    }
}
