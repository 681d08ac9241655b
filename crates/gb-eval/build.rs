//! Marks the tests that need the shared test data as ignored when it is missing: the check
//! lives in the gb-testdata crate (see its docs).

fn main() {
    gb_testdata::emit_build_script_cfg();
}
