// A 2 → 10 tanh layer followed by a layer that expects 11 inputs.
use controller_core::layer::Dense;
use controller_core::mlp::Hidden;

const NET: Hidden<2, 10, Dense<11, 1>> = Hidden::new(
    Dense::new([[0.0; 2]; 10], [0.0; 10]),
    Dense::new([[0.0; 11]; 1], [0.0; 1]),
);

fn main() {
    let _ = NET;
}
