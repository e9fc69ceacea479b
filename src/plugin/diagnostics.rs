//! Step diagnostics through `bevy_diagnostic`.

use bevy_app::{App, Plugin};
use bevy_diagnostic::{Diagnostic, DiagnosticPath, Diagnostics, RegisterDiagnostic};
use bevy_ecs::intern::Interned;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleLabel;

use super::{LastStep, MarblePluginSystems, stepped};
use crate::components::{Contacts, Marble, Quarantined};
use crate::pairs::MarbleContacts;
use crate::sleep::Sleeping;

/// The diagnostics' paths.
pub struct MarbleDiagnostics;

impl MarbleDiagnostics {
    /// Wall-clock time of the last physics step, ms.
    pub const STEP_TIME: DiagnosticPath = DiagnosticPath::const_new("marble/step_time");
    /// Marbles stepped (awake and not quarantined).
    pub const AWAKE: DiagnosticPath = DiagnosticPath::const_new("marble/awake");
    /// Marbles asleep.
    pub const ASLEEP: DiagnosticPath = DiagnosticPath::const_new("marble/asleep");
    /// Contacts of the last substep: marble–board and marble–marble.
    pub const CONTACTS: DiagnosticPath = DiagnosticPath::const_new("marble/contacts");
}

/// Step time, marbles awake and asleep and contacts, recorded after every step (read them
/// from `DiagnosticsStore`, or print them with Bevy's `LogDiagnosticsPlugin`).
pub struct MarbleDiagnosticsPlugin {
    pub(super) schedule: Interned<dyn ScheduleLabel>,
}

impl Plugin for MarbleDiagnosticsPlugin {
    fn build(&self, app: &mut App) {
        app.register_diagnostic(Diagnostic::new(MarbleDiagnostics::STEP_TIME).with_suffix(" ms"))
            .register_diagnostic(Diagnostic::new(MarbleDiagnostics::AWAKE))
            .register_diagnostic(Diagnostic::new(MarbleDiagnostics::ASLEEP))
            .register_diagnostic(Diagnostic::new(MarbleDiagnostics::CONTACTS));
        app.add_systems(
            self.schedule,
            record_diagnostics
                .run_if(stepped)
                .in_set(MarblePluginSystems::Record),
        );
    }
}

/// Records the last step's figures.
pub fn record_diagnostics(
    mut diagnostics: Diagnostics,
    last: Res<LastStep>,
    pairs: Res<MarbleContacts>,
    awake: Query<&Contacts, (With<Marble>, Without<Sleeping>, Without<Quarantined>)>,
    asleep: Query<(), (With<Marble>, With<Sleeping>)>,
) {
    diagnostics.add_measurement(&MarbleDiagnostics::STEP_TIME, || last.seconds * 1e3);
    diagnostics.add_measurement(&MarbleDiagnostics::AWAKE, || awake.iter().len() as f64);
    diagnostics.add_measurement(&MarbleDiagnostics::ASLEEP, || asleep.iter().len() as f64);
    diagnostics.add_measurement(&MarbleDiagnostics::CONTACTS, || {
        (awake.iter().map(Contacts::len).sum::<usize>() + pairs.len()) as f64
    });
}
