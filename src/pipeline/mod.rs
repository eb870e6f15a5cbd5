//! Point-cloud stages applied to a sweep after decoding (and deskewing).

pub mod config;
pub mod filter;
