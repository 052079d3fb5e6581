//! Placeholder: the contacts benchmark (canopy-parry world vs brute-force parry) is being
//! written.

fn main() {}
