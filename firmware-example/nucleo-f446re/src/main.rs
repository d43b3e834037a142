//! The certified pendulum controller on an ST Nucleo-F446RE (STM32F446RE, Cortex-M4F at
//! 168 MHz from the internal oscillator).
//!
//! TIM2 interrupts every Ts = `firmware_example::plant::TS` (0.05 s, the sampling time of
//! the pendulum problem the compiled-in weights were trained and certified for). Each
//! interrupt is one control step: read the sensors ([`plant::Plant::read`]), evaluate
//! `controller_core::demo::evaluate` (the compiled-in certified net, clamped, with flags), write
//! the actuator ([`plant::Plant::write`]) and log `k, x, u, flags` and the evaluation's
//! cycle count with defmt over RTT (shown by `probe-rs run`). The plant here is simulated
//! on the chip ([`plant::SimulatedPendulum`]): replace it by the rig's sensor and driver
//! code. The main loop sleeps (`wfi`) between interrupts.
#![no_std]
#![no_main]
#![deny(warnings)]

mod plant;

use core::cell::RefCell;
use cortex_m::interrupt::Mutex;
use cortex_m::peripheral::DWT;
use cortex_m_rt::entry;
use defmt_rtt as _;
use panic_probe as _;
use plant::{Plant, SimulatedPendulum};
use stm32f4xx_hal::{
    pac::{self, interrupt, Interrupt, TIM2},
    prelude::*,
    rcc::Config,
    timer::{CounterUs, Event},
};

/// The sampling period Ts in microseconds (TIM2's period).
const TS_US: u32 = (firmware_example::plant::TS * 1_000_000.0) as u32;

/// What the interrupt owns: the timer (to clear its flag), the plant and the step count.
struct Loop {
    timer: CounterUs<TIM2>,
    plant: SimulatedPendulum,
    k: u32,
}

static LOOP: Mutex<RefCell<Option<Loop>>> = Mutex::new(RefCell::new(None));

#[entry]
fn main() -> ! {
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        panic!("peripherals taken twice");
    };
    let mut rcc = dp.RCC.freeze(Config::hsi().sysclk(168.MHz()));
    // The cycle counter times each evaluation.
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    let c = &controller_core::demo::CERTIFICATE;
    defmt::info!(
        "ampc controller {}: eps {} (tanh {}), Ts {} us, sysclk {} Hz",
        c.hash,
        c.eps,
        c.tanh,
        TS_US,
        rcc.clocks.sysclk().raw()
    );
    let mut timer = dp.TIM2.counter_us(&mut rcc);
    if timer.start(TS_US.micros()).is_err() {
        panic!("TIM2 cannot run at Ts = {} us", TS_US);
    }
    timer.listen(Event::Update);
    cortex_m::interrupt::free(|cs| {
        LOOP.borrow(cs).replace(Some(Loop {
            timer,
            plant: SimulatedPendulum::hanging(),
            k: 0,
        }));
    });
    // SAFETY: the handler only touches `LOOP` inside a critical section.
    unsafe { cortex_m::peripheral::NVIC::unmask(Interrupt::TIM2) };
    loop {
        cortex_m::asm::wfi();
    }
}

/// One control step every Ts.
#[interrupt]
fn TIM2() {
    cortex_m::interrupt::free(|cs| {
        let mut guard = LOOP.borrow(cs).borrow_mut();
        let Some(l) = guard.as_mut() else { return };
        let _ = l.timer.wait();
        let x = l.plant.read();
        let t0 = DWT::cycle_count();
        let out = controller_core::demo::evaluate(&x);
        let cycles = DWT::cycle_count().wrapping_sub(t0);
        l.plant.write(out.u);
        defmt::info!(
            "k={} x={} u={} flags={=u8:#04x} cycles={}",
            l.k,
            x,
            out.u,
            out.flags.0,
            cycles
        );
        l.k = l.k.wrapping_add(1);
    });
}
