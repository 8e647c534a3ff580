//! A campaign's life on the coordinator: started ([`start`]), its tests
//! built once from its plan ([`tests_cache`]), shown ([`views`], with its
//! [`history`]), its events exported ([`events`]), and ended on request
//! ([`end`]). What happens to its reports is in `report/`.

pub mod end;
pub mod events;
pub mod history;
pub mod stage_size;
pub mod start;
pub mod tests_cache;
pub mod timeline;
pub mod views;
