// A crate's own controller goes through the same compile-time checks as the compiled-in
// one: a fallback outside the clamp band does not compile.
controller_core::include_controller!("own_weights/fallback_outside_band.rs");

fn main() {
    let _ = evaluate(&[0.0]);
}
