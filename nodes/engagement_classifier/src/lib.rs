//! engagement_classifier (in progress)
