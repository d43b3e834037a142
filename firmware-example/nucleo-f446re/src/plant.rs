//! The plant interface of the control loop — sensors in, actuator out — and its simulated
//! implementation for a bare board.
//!
//! A real rig implements [`Plant`] with its encoder / ADC reads (`read` → x in the
//! controller's physical units, x1 = θ − π [rad], x2 = ω [rad/s]) and its motor-driver write
//! (`write` ← u [N·m], already clamped by the controller to its certified band).

use controller_core::demo::{NU, NX};
use firmware_example::plant::rk4_step;

/// Sensor read and actuator write of one control step.
pub trait Plant {
    /// Measures the state x.
    fn read(&mut self) -> [f32; NX];
    /// Applies the input u until the next step (zero-order hold).
    fn write(&mut self, u: [f32; NU]);
}

/// The pendulum simulated on the chip: the QEMU example's f32 RK4 model
/// (`firmware_example::plant`, ẋ1 = x2, ẋ2 = u − 9.81·sin(x1 + π)); `write` advances it by
/// one sampling period Ts with u held.
pub struct SimulatedPendulum {
    x: [f32; NX],
}

impl SimulatedPendulum {
    /// The pendulum at rest hanging down, x = (−π, 0): the upswing's start.
    pub const fn hanging() -> Self {
        SimulatedPendulum {
            x: [-core::f32::consts::PI, 0.0],
        }
    }
}

impl Plant for SimulatedPendulum {
    fn read(&mut self) -> [f32; NX] {
        self.x
    }
    fn write(&mut self, u: [f32; NU]) {
        let [u] = u;
        self.x = rk4_step(self.x, u);
    }
}
