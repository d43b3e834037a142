//! The plot helpers: box-plot quartiles, tick labels, the viridis map, and PNG
//! rasterisation with the embedded font, the axis names of an expression plant.

use super::*;

#[test]
fn five_numbers_interpolate_quartiles() {
    assert_eq!(
        five_numbers(&[4.0, 0.0, 2.0, 1.0, 3.0, f64::NAN]),
        Some([0.0, 1.0, 2.0, 3.0, 4.0])
    );
    assert_eq!(five_numbers(&[1.0, 2.0]), Some([1.0, 1.25, 1.5, 1.75, 2.0]));
    assert_eq!(five_numbers(&[f64::NAN]), None);
}

#[test]
fn tick_labels_have_no_negative_zero() {
    let f = tick_fmt(2.0);
    assert_eq!(f(&-0.00001), "0.0");
    assert_eq!(f(&-0.25), "-0.2");
    assert_eq!(tick_fmt(30.0)(&-4.0), "-4");
    assert_eq!(tick_fmt(0.05)(&0.0123), "0.012");
}

#[test]
fn viridis_ends_and_clamps() {
    assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
    assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
    assert_eq!(viridis(2.0), viridis(1.0));
    assert_eq!(viridis(f64::NAN), viridis(0.0));
}

/// Text is rasterised with the embedded font: an SVG holding only text renders dark
/// pixels, and the PNG has the SVG's size × the scale.
#[test]
fn text_renders_with_the_embedded_font() {
    let svg = r#"<svg width="120" height="40" viewBox="0 0 120 40" xmlns="http://www.w3.org/2000/svg"><text x="5" y="28" font-family="sans-serif" font-size="24">κ x₁ 1.5</text></svg>"#;
    let png = to_png("t", svg, 2.0).unwrap();
    let pix = resvg::tiny_skia::Pixmap::decode_png(&png).unwrap();
    assert_eq!((pix.width(), pix.height()), (240, 80));
    let dark = pix.pixels().iter().filter(|p| p.red() < 100).count();
    assert!(dark > 200, "{dark} dark pixels: no text drawn");
    assert!(to_png("t", "<svg", 1.0).is_err());
}

#[test]
fn axis_names_of_expression_plants_are_their_names_with_units() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/pendulum_ode.toml");
    let cfg = crate::problem::ProblemConfig::load(std::path::Path::new(path)).unwrap();
    let (x, u) = axis_names(&cfg.system);
    assert_eq!(x, ["theta [rad]", "omega [rad/s]"]);
    assert_eq!(u, ["u [N*m]"]);
    assert_eq!(input_unit(&cfg.system), "[N*m]");
}
