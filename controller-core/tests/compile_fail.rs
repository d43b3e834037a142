//! Layer sizes that do not chain are a compile error (trybuild).
#![allow(clippy::indexing_slicing, clippy::unwrap_used)] // test code

#[test]
fn mismatched_layers_do_not_compile() {
    let t = trybuild::TestCases::new();
    t.compile_fail("tests/compile_fail/*.rs");
}
