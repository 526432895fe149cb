//! The `bag` node: records the suite's topics into an MCAP bag and plays bags back over DDS.
//! Reading and writing the files is the `bag_file` library's (`libs/bag_file`); this crate
//! adds the bus side (`dds_types`), the recorder's run loop on any bus (`recorder`) and the
//! two nodes' parameters.

pub mod dds_types;
pub mod params;
pub mod recorder;
