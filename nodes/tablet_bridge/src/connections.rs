//! The pages' connections and the guards on what they send, before any part of the core sees
//! it: at most `max_clients` connections; a token bucket of messages per connection (a flood
//! is dropped with one notice a second, then closed; the emergency stop always gets through);
//! text frames of at most `ws_max_message_bytes` in the page protocol's schema; and the PIN: a
//! therapist page logs in with it, a connection is closed after `pin_max_failures` wrong PINs,
//! and wrong PINs over all connections are limited to that many a minute.

use crate::io::{ClientId, Now, Output, log};
use crate::limits::{TokenBucket, pin_matches};
use crate::params::TabletBridgeParams;
use crate::protocol::{ClientMessage, CommandKind, Role, ServerMessage, parse_client_message};
use std::collections::BTreeMap;
use std::time::Duration;
use tracing::Level;

/// At most one "too many messages" notice per connection per this long.
const NOTICE_INTERVAL: Duration = Duration::from_secs(1);

struct Client {
    role: Role,
    bucket: TokenBucket,
    logged_in: bool,
    pin_failures: u32,
    dropped_in_a_row: u32,
    last_notice: Option<Duration>,
}

/// The pages connected, numbered in the order they came.
pub(crate) struct Connections {
    clients: BTreeMap<ClientId, Client>,
    next_id: ClientId,
    /// Wrong PINs left over all connections; refilled over a minute.
    pin_budget: TokenBucket,
}

impl Connections {
    pub(crate) fn new(params: &TabletBridgeParams, now: Now) -> Self {
        let failures = f64::from(params.pin_max_failures);
        Connections {
            clients: BTreeMap::new(),
            next_id: 1,
            pin_budget: TokenBucket::new(failures, failures / 60.0, now.monotonic),
        }
    }

    /// A page connected as `role`: its id, or why it is refused (too many are connected).
    pub(crate) fn open(
        &mut self,
        role: Role,
        params: &TabletBridgeParams,
        now: Now,
    ) -> Result<ClientId, String> {
        if self.clients.len() >= params.max_clients {
            let reason = format!(
                "too many tablet connections (at most {})",
                params.max_clients
            );
            return Err(reason);
        }
        let id = self.next_id;
        self.next_id += 1;
        let burst = f64::from(params.ws_burst);
        self.clients.insert(
            id,
            Client {
                role,
                bucket: TokenBucket::new(burst, params.ws_messages_per_second, now.monotonic),
                logged_in: false,
                pin_failures: 0,
                dropped_in_a_row: 0,
                last_notice: None,
            },
        );
        Ok(id)
    }

    /// Page `id` went: the role it had, if it was still connected.
    pub(crate) fn close(&mut self, id: ClientId) -> Option<Role> {
        self.clients.remove(&id).map(|c| c.role)
    }

    pub(crate) fn role(&self, id: ClientId) -> Option<Role> {
        self.clients.get(&id).map(|c| c.role)
    }

    pub(crate) fn logged_in(&self, id: ClientId) -> bool {
        self.clients.get(&id).is_some_and(|c| c.logged_in)
    }

    /// A binary frame of `len` bytes from page `id`: refused (the pages never send one).
    pub(crate) fn binary(
        &mut self,
        id: ClientId,
        len: usize,
        params: &TabletBridgeParams,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        if self.take_token(id, params, now, out) {
            self.reject(
                id,
                format!("binary messages ({len} bytes) are not accepted"),
                out,
            );
        }
    }

    /// A text frame from page `id`: the message in it, if it passes rate, size and schema.
    pub(crate) fn text(
        &mut self,
        id: ClientId,
        text: &str,
        params: &TabletBridgeParams,
        now: Now,
        out: &mut Vec<Output>,
    ) -> Option<ClientMessage> {
        let max = params.ws_max_message_bytes;
        if !self.take_token(id, params, now, out) {
            // The emergency stop is never refused for rate: the therapist may be tapping it
            // while the connection is flooded.
            let emergency = text.len() <= max
                && matches!(
                    parse_client_message(text),
                    Ok(ClientMessage::Command {
                        command: CommandKind::EmergencyStop,
                        ..
                    })
                );
            if !emergency || !self.clients.contains_key(&id) {
                return None;
            }
        }
        if text.len() > max {
            let reason = format!(
                "message of {} bytes is over the limit of {max} bytes",
                text.len()
            );
            self.reject(id, reason, out);
            return None;
        }
        match parse_client_message(text) {
            Err(reason) => {
                self.reject(id, reason, out);
                None
            }
            Ok(message) => Some(message),
        }
    }

    /// Takes a rate token for `id`; when there is none, counts the drop, sends a notice at
    /// most once a second and closes a connection that keeps flooding.
    fn take_token(
        &mut self,
        id: ClientId,
        params: &TabletBridgeParams,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        let (rate, burst) = (params.ws_messages_per_second, params.ws_burst);
        let max_dropped = params.ws_max_dropped_before_close;
        let Some(c) = self.clients.get_mut(&id) else {
            return false;
        };
        if c.bucket.try_take(now.monotonic) {
            c.dropped_in_a_row = 0;
            return true;
        }
        c.dropped_in_a_row += 1;
        if c.dropped_in_a_row >= max_dropped {
            let reason = format!("closed: {max_dropped} messages in a row over the rate limit");
            out.push(log(
                Level::WARN,
                format!("page {id} ({:?}): {reason}", c.role),
            ));
            out.push(Output::Send(
                id,
                ServerMessage::Rejected {
                    reason: reason.clone(),
                },
            ));
            out.push(Output::Close(id, reason));
            self.clients.remove(&id);
        } else if c
            .last_notice
            .is_none_or(|t| now.monotonic.saturating_sub(t) >= NOTICE_INTERVAL)
        {
            c.last_notice = Some(now.monotonic);
            let reason = format!(
                "too many messages: at most {rate} per second (bursts of {burst}); {} dropped",
                c.dropped_in_a_row
            );
            out.push(log(
                Level::WARN,
                format!("page {id} ({:?}): {reason}", c.role),
            ));
            out.push(Output::Send(id, ServerMessage::Rejected { reason }));
        }
        false
    }

    /// A login with `pin` from page `id`: true when the page is logged in (now or already),
    /// and is to be shown what a therapist page shows; refused with the reason otherwise.
    pub(crate) fn log_in(
        &mut self,
        id: ClientId,
        pin: &str,
        params: &TabletBridgeParams,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        if self.logged_in(id) {
            return true;
        }
        if !self.pin_budget.has_token(now.monotonic) {
            let wait = self.pin_budget.wait_secs(now.monotonic).ceil();
            let reason = format!("too many wrong PINs: try again in {wait} s");
            self.reject(id, reason, out);
            return false;
        }
        if !pin_matches(pin, &params.pin) {
            self.wrong_pin(id, params, now, out);
            return false;
        }
        if let Some(c) = self.clients.get_mut(&id) {
            c.logged_in = true;
            c.pin_failures = 0;
        }
        out.push(log(Level::INFO, format!("page {id}: therapist logged in")));
        true
    }

    /// Whether a command from page `id` may go on: it is logged in and `pin` is the PIN;
    /// refused with the reason otherwise.
    pub(crate) fn may_command(
        &mut self,
        id: ClientId,
        pin: &str,
        params: &TabletBridgeParams,
        now: Now,
        out: &mut Vec<Output>,
    ) -> bool {
        if !self.logged_in(id) {
            self.reject(id, "log in with the PIN first".into(), out);
            return false;
        }
        if !pin_matches(pin, &params.pin) {
            self.wrong_pin(id, params, now, out);
            return false;
        }
        true
    }

    fn wrong_pin(
        &mut self,
        id: ClientId,
        params: &TabletBridgeParams,
        now: Now,
        out: &mut Vec<Output>,
    ) {
        self.pin_budget.try_take(now.monotonic);
        let max = params.pin_max_failures;
        let Some(c) = self.clients.get_mut(&id) else {
            return;
        };
        c.pin_failures += 1;
        let failures = c.pin_failures;
        self.reject(id, "wrong PIN".into(), out);
        if failures >= max {
            let reason = format!("closed after {failures} wrong PINs");
            out.push(log(Level::WARN, format!("page {id}: {reason}")));
            out.push(Output::Close(id, reason));
            self.clients.remove(&id);
        }
    }

    /// Refuses what page `id` sent: logged, and the reason goes back to the page.
    pub(crate) fn reject(&self, id: ClientId, reason: String, out: &mut Vec<Output>) {
        let role = self.role(id);
        out.push(log(
            Level::WARN,
            format!("page {id} ({role:?}) rejected: {reason}"),
        ));
        out.push(Output::Send(id, ServerMessage::Rejected { reason }));
    }

    /// Sends `message` to every child page, or every logged-in therapist page.
    pub(crate) fn broadcast(&self, role: Role, message: &ServerMessage, out: &mut Vec<Output>) {
        self.send_to(role, None, message, out);
    }

    /// As [`Self::broadcast`], to every such page but `except`.
    pub(crate) fn send_to(
        &self,
        role: Role,
        except: Option<ClientId>,
        message: &ServerMessage,
        out: &mut Vec<Output>,
    ) {
        for (id, c) in &self.clients {
            if c.role == role && (role == Role::Child || c.logged_in) && Some(*id) != except {
                out.push(Output::Send(*id, message.clone()));
            }
        }
    }
}
