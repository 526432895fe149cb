//! The paper's evaluation in simulation: the grid of user models × rewards and transfers
//! (`grid`), and its outputs in words and numbers (`report`); the figures are `plots`'.

pub mod grid;
pub mod report;
