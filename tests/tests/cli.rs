//! The CLI's own behaviour.

use gb_tests::xtask;

#[test]
fn unknown_device_is_a_clear_error_with_exit_code_2() {
    let out = xtask(&["devices", "--device", "cuda"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cuda"), "{err}");
}

#[test]
fn devices_lists_flex_as_working() {
    let out = xtask(&["devices", "--device", "flex"]);
    assert!(out.status.success());
    let s = String::from_utf8_lossy(&out.stdout);
    assert!(s.contains("flex") && s.contains("ok"), "{s}");
}
