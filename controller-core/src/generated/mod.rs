//! `generated`: files written by `trainer export` (do not edit them by hand).

pub mod weights;
