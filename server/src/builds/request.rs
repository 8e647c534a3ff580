//! A library request's threshold and search, checked before any build.

use tslg_api::{CreateLibrary, SearchRequest};
use tslg_method::registry::{BuildRequest, LibrarySearch};

/// The method's threshold and search from the request, validated; what the
/// request leaves out is the case's default.
pub fn build_request(req: &CreateLibrary) -> Result<BuildRequest, String> {
    let threshold = req.threshold.map(tslg_client::wire::threshold);
    if let Some(t) = threshold {
        t.validate().map_err(|e| e.to_string())?;
    }
    if let Some(SearchRequest::Multistart { starts, .. }) = req.search {
        if !(1..=100_000).contains(&starts) {
            return Err(format!("search.starts = {starts} must be in 1..=100000"));
        }
    }
    let search = req.search.map(tslg_client::wire::library_search);
    if let Some(LibrarySearch::Policy(solver)) = search {
        solver.validate()?;
    }
    Ok(BuildRequest { threshold, search })
}
