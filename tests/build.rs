//! Marks the tests that need the shared test data as ignored when it is missing: the check
//! lives in gb-core's `testdata.rs`, compiled here as a module (see its docs).

#[allow(dead_code)]
#[path = "../crates/gb-core/src/testdata.rs"]
mod testdata;

fn main() {
    testdata::emit_build_script_cfg();
}
