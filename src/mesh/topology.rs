//! topology
pub struct Topology;
