//! Growing one regression tree on gradient pairs the way xgboost's `grow_colmaker` does:
//! level by level, each column scanned backward (missing values default left) and, when the
//! column has missing values, forward too (default right); gains in f32 from f64 sums;
//! ties go to the lower feature index.

use super::{TrainParams, TrainingData};
use crate::features::FEATURE_COUNT;

/// xgboost's `kRtEps`.
const RT_EPS: f32 = 1e-6;

/// Sum of gradients and hessians (f64, as xgboost's `GradStats`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GradStats {
    pub grad: f64,
    pub hess: f64,
}

impl GradStats {
    fn add(&mut self, o: GradStats) {
        self.grad += o.grad;
        self.hess += o.hess;
    }
    fn minus(self, o: GradStats) -> GradStats {
        GradStats {
            grad: self.grad - o.grad,
            hess: self.hess - o.hess,
        }
    }
}

/// A node in xgboost's numbering (allocation order): children of a split are allocated
/// together when it is expanded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TreeNode {
    pub parent: i32,
    /// -1 for a leaf.
    pub left: i32,
    pub right: i32,
    /// Model column of the split (0 for a leaf).
    pub feature: u32,
    /// Split threshold, or the leaf value (already scaled by the learning rate).
    pub value: f32,
    pub default_left: bool,
    pub base_weight: f32,
    pub loss_change: f32,
    pub sum_hess: f32,
}

#[derive(Debug, Clone, Default)]
pub struct TrainedTree {
    pub nodes: Vec<TreeNode>,
}

/// A candidate split (xgboost's `SplitEntry`).
#[derive(Debug, Clone, Copy, Default)]
struct Split {
    loss_change: f32,
    feature: u32,
    value: f32,
    default_left: bool,
}

impl Split {
    /// Replace when better; on equal gain the lower feature index wins.
    fn offer(&mut self, candidate: Split) {
        let replace = if candidate.loss_change.is_infinite() {
            false
        } else if self.feature <= candidate.feature {
            candidate.loss_change > self.loss_change
        } else {
            // xgboost: `!(current > new)`, which a NaN also satisfies.
            self.loss_change.partial_cmp(&candidate.loss_change)
                != Some(std::cmp::Ordering::Greater)
        };
        if replace {
            *self = candidate;
        }
    }
}

/// Per-node state while growing.
#[derive(Debug, Clone, Copy, Default)]
struct NodeEntry {
    stats: GradStats,
    root_gain: f32,
    weight: f32,
    best: Split,
}

/// Per-node scan state for one column direction.
#[derive(Debug, Clone, Copy, Default)]
struct ScanEntry {
    stats: GradStats,
    last_value: f32,
}

struct Grower<'a> {
    params: &'a TrainParams,
    gradients: &'a [GradStats],
    nodes: Vec<TreeNode>,
    entries: Vec<NodeEntry>,
    /// Node of each row; `!node` (negative) once the row sits in a finished leaf.
    position: Vec<i32>,
}

impl Grower<'_> {
    fn weight(&self, s: GradStats) -> f32 {
        let mcw = f64::from(self.params.min_child_weight);
        if s.hess < mcw || s.hess <= 0.0 {
            return 0.0;
        }
        (-s.grad / (s.hess + f64::from(self.params.reg_lambda))) as f32
    }

    fn gain(&self, s: GradStats) -> f32 {
        if s.hess <= 0.0 {
            return 0.0;
        }
        (s.grad * s.grad) as f32 / (s.hess + f64::from(self.params.reg_lambda)) as f32
    }

    fn new_leaf(&mut self, parent: i32) -> i32 {
        self.nodes.push(TreeNode {
            parent,
            left: -1,
            right: -1,
            feature: 0,
            value: 0.0,
            default_left: false,
            base_weight: 0.0,
            loss_change: 0.0,
            sum_hess: 0.0,
        });
        self.entries.push(NodeEntry::default());
        (self.nodes.len() - 1) as i32
    }

    /// Sums the gradients of the active rows of `nodes` and sets their weight and gain.
    fn init_nodes(&mut self, nodes: &[i32]) {
        for &nid in nodes {
            self.entries[nid as usize].stats = GradStats::default();
        }
        for (row, &pos) in self.position.iter().enumerate() {
            if pos >= 0 {
                self.entries[pos as usize].stats.add(self.gradients[row]);
            }
        }
        for &nid in nodes {
            let stats = self.entries[nid as usize].stats;
            self.entries[nid as usize].weight = self.weight(stats);
            self.entries[nid as usize].root_gain = self.gain(stats);
        }
    }

    fn candidate(
        &self,
        nid: usize,
        feature: u32,
        value: f32,
        forward: bool,
        scanned: GradStats,
    ) -> Split {
        let rest = self.entries[nid].stats.minus(scanned);
        // Backward scans accumulate the right side; forward scans the left side.
        let (left, right) = if forward {
            (scanned, rest)
        } else {
            (rest, scanned)
        };
        let gain = self.gain(left) + self.gain(right);
        Split {
            loss_change: gain - self.entries[nid].root_gain,
            feature,
            value,
            default_left: !forward,
        }
    }

    /// One pass over a sorted column in one direction, for all nodes being expanded.
    fn scan(&mut self, column: &[(f32, u32)], feature: u32, forward: bool, expand: &[i32]) {
        let mcw = f64::from(self.params.min_child_weight);
        let mut scan = vec![ScanEntry::default(); self.nodes.len()];
        let mut visit = |&(value, row): &(f32, u32), g: &mut Self| {
            let pos = g.position[row as usize];
            if pos < 0 {
                return;
            }
            let nid = pos as usize;
            let e = scan[nid];
            if e.stats.hess != 0.0
                && value != e.last_value
                && e.stats.hess >= mcw
                && g.entries[nid].stats.minus(e.stats).hess >= mcw
            {
                let proposed = (value + e.last_value) * 0.5;
                let split_at = if proposed == value {
                    e.last_value
                } else {
                    proposed
                };
                let c = g.candidate(nid, feature, split_at, forward, e.stats);
                g.entries[nid].best.offer(c);
            }
            scan[nid].stats.add(g.gradients[row as usize]);
            scan[nid].last_value = value;
        };
        if forward {
            column.iter().for_each(|e| visit(e, self));
        } else {
            column.iter().rev().for_each(|e| visit(e, self));
        }
        // All non-missing rows on the scanned side, missing ones on the other.
        for &nid in expand {
            let nid = nid as usize;
            let e = scan[nid];
            let rest = self.entries[nid].stats.minus(e.stats);
            if e.stats.hess >= mcw && rest.hess >= mcw {
                let gap = e.last_value.abs() + RT_EPS;
                let split_at = e.last_value + if forward { gap } else { -gap };
                let c = self.candidate(nid, feature, split_at, forward, e.stats);
                self.entries[nid].best.offer(c);
            }
        }
    }

    /// Finds and applies the best split of every node in `expand`.
    fn find_splits(&mut self, data: &TrainingData, expand: &[i32]) {
        let n_rows = data.len() as f32;
        for (j, column) in data.sorted.iter().enumerate() {
            let density = 1.0 - (data.len() - column.len()) as f32 / n_rows;
            let indicator = !column.is_empty() && column[0].0 == column[column.len() - 1].0;
            if density < 1.0 && !indicator {
                self.scan(column, j as u32, true, expand);
            }
            self.scan(column, j as u32, false, expand);
        }
        let eta = self.params.learning_rate;
        for &nid in expand {
            let e = self.entries[nid as usize];
            if e.best.loss_change > RT_EPS {
                let left = self.new_leaf(nid);
                let right = self.new_leaf(nid);
                let node = &mut self.nodes[nid as usize];
                node.left = left;
                node.right = right;
                node.feature = e.best.feature;
                node.value = e.best.value;
                node.default_left = e.best.default_left;
            } else {
                self.nodes[nid as usize].value = e.weight * eta;
            }
        }
    }

    /// Moves rows of split nodes to their children; rows of new leaves stop.
    fn reset_positions(&mut self, data: &TrainingData) {
        for (row, pos) in self.position.iter_mut().enumerate() {
            if *pos < 0 {
                continue;
            }
            let node = self.nodes[*pos as usize];
            if node.left == -1 {
                *pos = !*pos;
                continue;
            }
            let v = data.rows[row][node.feature as usize];
            let go_left = if v.is_nan() {
                node.default_left
            } else {
                v < node.value
            };
            *pos = if go_left { node.left } else { node.right };
        }
    }
}

/// Grows one tree; returns it with the leaf each training row ends in.
pub(super) fn grow(
    data: &TrainingData,
    gradients: &[GradStats],
    params: &TrainParams,
) -> (TrainedTree, Vec<i32>) {
    let mut g = Grower {
        params,
        gradients,
        nodes: Vec::with_capacity(1 << (params.max_depth.min(10) + 1)),
        entries: Vec::new(),
        position: vec![0; data.len()],
    };
    g.new_leaf(i32::MAX);
    let mut expand = vec![0i32];
    g.init_nodes(&expand);
    for _depth in 0..params.max_depth {
        g.find_splits(data, &expand);
        g.reset_positions(data);
        let children: Vec<i32> = expand
            .iter()
            .filter(|&&nid| g.nodes[nid as usize].left != -1)
            .flat_map(|&nid| [g.nodes[nid as usize].left, g.nodes[nid as usize].right])
            .collect();
        g.init_nodes(&children);
        expand = children;
        if expand.is_empty() {
            break;
        }
    }
    let eta = params.learning_rate;
    for &nid in &expand {
        g.nodes[nid as usize].value = g.entries[nid as usize].weight * eta;
    }
    for (node, e) in g.nodes.iter_mut().zip(&g.entries) {
        node.loss_change = e.best.loss_change;
        node.base_weight = e.weight;
        node.sum_hess = e.stats.hess as f32;
    }
    let leaves = g
        .position
        .iter()
        .map(|&p| if p < 0 { !p } else { p })
        .collect();
    debug_assert!(g.nodes.iter().all(|n| (n.feature as usize) < FEATURE_COUNT));
    (TrainedTree { nodes: g.nodes }, leaves)
}
