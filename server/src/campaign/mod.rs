//! A campaign's life on the coordinator: started ([`start`], an adaptive
//! one's stage length sized from the fleet by [`stage_size`]), its tests
//! built once from its plan (`report/tests_cache.rs`), shown ([`views`], with its
//! [`history`], its [`verdict`] and its [`timeline`]), its events exported
//! ([`events`]), and ended on request ([`end`]). What happens to its
//! reports is in `report/`.

pub mod end;
pub mod events;
pub mod history;
pub mod stage_size;
pub mod start;
pub mod timeline;
pub mod verdict;
pub mod views;
