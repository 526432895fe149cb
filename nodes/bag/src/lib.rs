//! The `bag` node: records the suite's topics over DDS into an MCAP bag and plays bags back.
//! Reading and writing the files is the `bag` library's (`libs/bag`); this crate adds the DDS
//! side and the two nodes' parameters.

pub mod dds_types;
pub mod params;
