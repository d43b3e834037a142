//! `by_nz!`: the dispatch from a run-time dual size to a compile-time one. The AD kernels of
//! the plants are generic over `NZ = nx + nu` (num-dual's static dual vectors); this macro
//! calls `$self.$method::<NZ>(args)` with `NZ` equal to the run-time `$nz` for every
//! `NZ ∈ 1..=16` (= `MAX_NZ`, which the caller has in scope; a larger size is refused by
//! validation before any plant is built). Used by the expression plants, their sweeps and
//! constraints, and the plants implemented in Rust (`custom`).

/// Calls `$self.$method::<NZ>(args)` with the constant `NZ` equal to `$nz`.
macro_rules! by_nz {
    ($nz:expr, $self:ident . $method:ident $args:tt) => {
        by_nz!(@ $nz, $self.$method $args, 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
    };
    (@ $nz:expr, $self:ident . $method:ident $args:tt, $($n:literal)*) => {
        match $nz {
            $($n => $self.$method::<$n> $args,)*
            n => panic!("plant with nx + nu = {n} > {MAX_NZ} (rejected by validate)"),
        }
    };
}
/// The dispatch for every plant of `model` (expression, sweep, constraint, custom).
pub(super) use by_nz;
