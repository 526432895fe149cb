//! The game side of the core: what the therapist page keeps of the game besides its state
//! (decisions, results with the running tally of their session, and engagement), so a page
//! that logs in mid-session shows the session so far.

use crate::protocol::{DecisionView, EngagementPoint, ResultView};
use qt_therapy_msgs::{Decision, ExpectedEngagement, SequenceResult};
use session_tally::Tally;
use std::collections::VecDeque;

/// Decisions and results kept for a therapist page that logs in mid-session.
const HISTORY: usize = 50;

/// The session so far, as the therapist page shows it.
#[derive(Debug, Default)]
pub(crate) struct GameHistory {
    pub(crate) engagement: VecDeque<EngagementPoint>,
    pub(crate) decisions: VecDeque<DecisionView>,
    pub(crate) results: VecDeque<ResultView>,
    /// The results of the session the newest result belongs to, for its running tally.
    session_results: Vec<SequenceResult>,
}

impl GameHistory {
    /// A policy decision: kept, and its view for the therapist pages.
    pub(crate) fn decision(&mut self, d: &Decision) -> DecisionView {
        let view = DecisionView::of(d);
        push_for_session(&mut self.decisions, view.clone(), |v| &v.session_id);
        view
    }

    /// A sequence's result: kept with its session's tally so far, and its view for the
    /// therapist pages.
    pub(crate) fn result(&mut self, r: SequenceResult) -> ResultView {
        if self
            .session_results
            .last()
            .is_some_and(|last| last.session_id != r.session_id)
        {
            self.session_results.clear();
        }
        // A result delivered again (the topic keeps its history) counts once.
        self.session_results
            .retain(|k| k.sequence_index != r.sequence_index);
        self.session_results.push(r.clone());
        let view = ResultView::of(r, &Tally::of(&self.session_results));
        push_for_session(&mut self.results, view.clone(), ResultView::session_id);
        view
    }

    /// An engagement window: kept (the newest `limit`), and its point for the therapist
    /// pages.
    pub(crate) fn engagement(&mut self, e: &ExpectedEngagement, limit: usize) -> EngagementPoint {
        let point = EngagementPoint::of(e);
        if self.engagement.len() >= limit {
            self.engagement.pop_front();
        }
        self.engagement.push_back(point.clone());
        point
    }
}

/// Appends to a per-session history, starting over when the session changes.
fn push_for_session<T>(list: &mut VecDeque<T>, item: T, session: impl Fn(&T) -> &String) {
    if list
        .back()
        .is_some_and(|last| session(last) != session(&item))
    {
        list.clear();
    }
    if list.len() >= HISTORY {
        list.pop_front();
    }
    list.push_back(item);
}
