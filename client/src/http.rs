//! A client of the coordinator's HTTP API: the worker's calls (leases,
//! results, plans) and the user's (libraries, campaigns), with problem
//! responses turned into [`CallError::Refused`] carrying the server's detail.

use reqwest::StatusCode;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tslg_api::{
    CampaignPlan, CampaignView, CreateCampaign, CreateLibrary, HeartbeatAck, History, Lease,
    LeaseFence, LeaseRelease, LeaseRequest, LibraryUpload, LibraryView, Problem, ResultAck,
    ResultReport, WorkerCredential, WorkerRegistration, WORKER_SECRET_HEADER,
};

/// A failed call: worth retrying, or refused for good.
#[derive(Debug, thiserror::Error)]
pub enum CallError {
    /// The coordinator could not be reached or failed (5xx): retry later.
    #[error("coordinator unavailable: {0}")]
    Transient(String),
    /// The coordinator refused the request (4xx) with this problem.
    #[error("refused ({status}): {detail}")]
    Refused {
        /// The HTTP status.
        status: u16,
        /// The problem's `detail`.
        detail: String,
    },
}

/// A coordinator's HTTP client, with its base URL and bearer token, and
/// the secrets of the workers it registered (shared by its clones).
#[derive(Clone)]
pub struct Client {
    http: reqwest::Client,
    base: String,
    token: Option<String>,
    secrets: Arc<Mutex<HashMap<String, String>>>,
    /// Registrations one at a time: two calls naming a new worker at once
    /// register it once.
    registering: Arc<tokio::sync::Mutex<()>>,
}

impl Client {
    /// A client of the coordinator at `base`, sending `token` as a bearer token if given.
    pub fn new(base: &str, token: Option<String>) -> anyhow::Result<Self> {
        let http = reqwest::Client::builder()
            .connect_timeout(Duration::from_secs(5))
            .timeout(Duration::from_secs(60))
            .build()?;
        Ok(Self {
            http,
            base: base.trim_end_matches('/').to_owned(),
            token,
            secrets: Arc::default(),
            registering: Arc::default(),
        })
    }

    /// `POST /api/v1/workers`: registers a worker asking for `name`; the
    /// credential is kept for the requests that name the worker issued
    /// (which is `name`, or `name.k` when `name` was issued before).
    pub async fn register(&self, name: &str) -> Result<WorkerCredential, CallError> {
        self.register_enrolled(name, None).await
    }

    /// [`Self::register`] with an enrolment secret an administrator issued
    /// (`POST /api/v1/enrolments`): the worker belongs to its principal.
    pub async fn register_enrolled(
        &self,
        name: &str,
        enrolment: Option<&str>,
    ) -> Result<WorkerCredential, CallError> {
        let registration = WorkerRegistration {
            name: name.into(),
            enrolment: enrolment.map(str::to_owned),
        };
        let issued: WorkerCredential = self.post("/api/v1/workers", &registration).await?;
        self.use_credential(&issued.name, &issued.secret);
        Ok(issued)
    }

    /// Sends `secret` with every request that names `worker`.
    pub fn use_credential(&self, worker: &str, secret: &str) {
        let mut secrets = self.secrets.lock().unwrap_or_else(|p| p.into_inner());
        secrets.insert(worker.to_owned(), secret.to_owned());
    }

    /// The secret this client sends for `worker`, if it registered it (for
    /// a request built by hand).
    pub fn secret_of(&self, worker: &str) -> Option<String> {
        let secrets = self.secrets.lock().unwrap_or_else(|p| p.into_inner());
        secrets.get(worker).cloned()
    }

    /// `POST path` with `body`, in `worker`'s name: carrying its secret. A
    /// worker this client has no credential for is registered first, under
    /// its name: when that name was issued to another worker, the call is
    /// refused (409) rather than made in another name.
    async fn worker_post<B: Serialize>(
        &self,
        path: &str,
        body: &B,
        worker: &str,
    ) -> Result<reqwest::RequestBuilder, CallError> {
        let builder = self.request(reqwest::Method::POST, path).json(body);
        if let Some(secret) = self.secret_of(worker) {
            return Ok(builder.header(WORKER_SECRET_HEADER, secret));
        }
        let _one = self.registering.lock().await;
        let secret = match self.secret_of(worker) {
            Some(secret) => secret,
            None => {
                let issued = self.register(worker).await?;
                if issued.name != worker {
                    return Err(CallError::Refused {
                        status: 409,
                        detail: format!(
                            "worker name `{worker}` was issued before; the coordinator \
                             registered this worker as `{}`: name it so",
                            issued.name
                        ),
                    });
                }
                issued.secret
            }
        };
        Ok(builder.header(WORKER_SECRET_HEADER, secret))
    }

    fn request(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        let builder = self.http.request(method, format!("{}{path}", self.base));
        match &self.token {
            Some(t) => builder.bearer_auth(t),
            None => builder,
        }
    }

    async fn send(&self, builder: reqwest::RequestBuilder) -> Result<reqwest::Response, CallError> {
        let response = builder.send().await.map_err(|e| {
            if e.is_connect() {
                CallError::Transient(format!(
                    "cannot connect to the coordinator at {}: is it running there? ({e})",
                    self.base
                ))
            } else if e.is_timeout() {
                CallError::Transient(format!(
                    "the coordinator at {} did not answer in time ({e})",
                    self.base
                ))
            } else {
                CallError::Transient(e.to_string())
            }
        })?;
        let status = response.status();
        if status.is_server_error() {
            return Err(CallError::Transient(format!("HTTP {status}")));
        }
        if status.is_client_error() {
            let detail = match response.json::<Problem>().await {
                Ok(p) => p.detail,
                Err(_) => status.to_string(),
            };
            return Err(CallError::Refused {
                status: status.as_u16(),
                detail,
            });
        }
        Ok(response)
    }

    async fn json<T: DeserializeOwned>(
        &self,
        builder: reqwest::RequestBuilder,
    ) -> Result<T, CallError> {
        self.send(builder)
            .await?
            .json()
            .await
            .map_err(|e| CallError::Transient(format!("unreadable answer: {e}")))
    }

    async fn post<B: Serialize, T: DeserializeOwned>(
        &self,
        path: &str,
        body: &B,
    ) -> Result<T, CallError> {
        self.json(self.request(reqwest::Method::POST, path).json(body))
            .await
    }

    /// A lease, or `None` when there is no work.
    pub async fn claim(&self, request: &LeaseRequest) -> Result<Option<Lease>, CallError> {
        let response = self
            .send(
                self.worker_post("/api/v1/leases", request, &request.worker)
                    .await?,
            )
            .await?;
        if response.status() == StatusCode::NO_CONTENT {
            return Ok(None);
        }
        response
            .json()
            .await
            .map(Some)
            .map_err(|e| CallError::Transient(format!("unreadable lease: {e}")))
    }

    /// `POST /api/v1/leases/{lease}/heartbeat`: extends the lease.
    pub async fn heartbeat(
        &self,
        lease: i64,
        fence: &LeaseFence,
    ) -> Result<HeartbeatAck, CallError> {
        let path = format!("/api/v1/leases/{lease}/heartbeat");
        self.json(self.worker_post(&path, fence, &fence.worker).await?)
            .await
    }

    /// `POST /api/v1/workers/{worker}/leave`: the worker is leaving (after
    /// giving its leases back); it is out of the live fleet at once.
    pub async fn leave(&self, worker: &str) -> Result<(), CallError> {
        let path = format!("/api/v1/workers/{worker}/leave");
        self.send(
            self.worker_post(&path, &serde_json::json!({}), worker)
                .await?,
        )
        .await
        .map(|_| ())
    }

    /// `POST /api/v1/leases/{lease}/release`: gives the rest of the lease back.
    pub async fn release(&self, lease: i64, release: &LeaseRelease) -> Result<(), CallError> {
        let path = format!("/api/v1/leases/{lease}/release");
        self.send(self.worker_post(&path, release, &release.worker).await?)
            .await
            .map(|_| ())
    }

    /// `POST /api/v1/leases/{lease}/results`: reports a range of outcomes.
    pub async fn report(&self, lease: i64, report: &ResultReport) -> Result<ResultAck, CallError> {
        let path = format!("/api/v1/leases/{lease}/results");
        self.json(self.worker_post(&path, report, &report.worker).await?)
            .await
    }

    /// `POST /api/v1/leases/{lease}/library`: the library a worker built
    /// whole for a campaign of method `build` (or why it failed).
    pub async fn upload_library(
        &self,
        lease: i64,
        upload: &LibraryUpload,
    ) -> Result<(), CallError> {
        let path = format!("/api/v1/leases/{lease}/library");
        self.send(self.worker_post(&path, upload, &upload.worker).await?)
            .await
            .map(|_| ())
    }

    /// `GET /api/v1/campaigns/{campaign}/plan`: what any test of it needs.
    pub async fn plan(&self, campaign: i64) -> Result<CampaignPlan, CallError> {
        self.json(self.request(
            reqwest::Method::GET,
            &format!("/api/v1/campaigns/{campaign}/plan"),
        ))
        .await
    }

    /// The library file's bytes, in its case's format.
    pub async fn library_file(&self, library: i64) -> Result<Vec<u8>, CallError> {
        let bytes = self
            .send(self.request(
                reqwest::Method::GET,
                &format!("/api/v1/libraries/{library}/file"),
            ))
            .await?
            .bytes()
            .await
            .map_err(|e| CallError::Transient(e.to_string()))?;
        Ok(bytes.to_vec())
    }

    /// `GET /metrics`: the Prometheus text.
    pub async fn metrics(&self) -> Result<String, CallError> {
        self.send(self.request(reqwest::Method::GET, "/metrics"))
            .await?
            .text()
            .await
            .map_err(|e| CallError::Transient(e.to_string()))
    }

    /// `GET /healthz`.
    pub async fn health(&self) -> Result<tslg_api::Health, CallError> {
        self.json(self.request(reqwest::Method::GET, "/healthz"))
            .await
    }

    /// `POST /api/v1/libraries`: starts a library build.
    pub async fn create_library(&self, request: &CreateLibrary) -> Result<LibraryView, CallError> {
        self.post("/api/v1/libraries", request).await
    }

    /// `POST /api/v1/cases`: defines a user-defined case.
    pub async fn create_case(
        &self,
        request: &tslg_api::CreateCase,
    ) -> Result<tslg_api::CaseView, CallError> {
        self.post("/api/v1/cases", request).await
    }

    /// `GET /api/v1/cases`: every case the coordinator runs.
    pub async fn cases(&self) -> Result<Vec<tslg_api::CaseView>, CallError> {
        self.json(self.request(reqwest::Method::GET, "/api/v1/cases"))
            .await
    }

    /// `GET /api/v1/libraries/{id}`.
    pub async fn library(&self, id: i64) -> Result<LibraryView, CallError> {
        self.json(self.request(reqwest::Method::GET, &format!("/api/v1/libraries/{id}")))
            .await
    }

    /// `POST /api/v1/enrolments` (admin): an enrolment credential for
    /// `principal`; the secret is shown this once.
    pub async fn enrol(&self, principal: &str) -> Result<tslg_api::Enrolment, CallError> {
        let request = tslg_api::EnrolmentRequest {
            principal: principal.into(),
        };
        self.post("/api/v1/enrolments", &request).await
    }

    /// `POST /api/v1/campaigns`: starts a campaign.
    pub async fn create_campaign(
        &self,
        request: &CreateCampaign,
    ) -> Result<CampaignView, CallError> {
        self.post("/api/v1/campaigns", request).await
    }

    /// Every campaign, newest first.
    pub async fn campaigns(&self) -> Result<tslg_api::CampaignList, CallError> {
        self.campaigns_in(None).await
    }

    /// Every campaign, or those in `status` (`?status=`), newest first.
    pub async fn campaigns_in(
        &self,
        status: Option<tslg_api::CampaignStatus>,
    ) -> Result<tslg_api::CampaignList, CallError> {
        let path = match status {
            Some(s) => format!("/api/v1/campaigns?status={}", s.as_str()),
            None => "/api/v1/campaigns".to_owned(),
        };
        self.json(self.request(reqwest::Method::GET, &path)).await
    }

    /// Every library, or those in `status` (`?status=`), newest first.
    pub async fn libraries(
        &self,
        status: Option<tslg_api::LibraryStatus>,
    ) -> Result<Vec<LibraryView>, CallError> {
        let path = match status {
            Some(s) => format!("/api/v1/libraries?status={}", s.as_str()),
            None => "/api/v1/libraries".to_owned(),
        };
        self.json(self.request(reqwest::Method::GET, &path)).await
    }

    /// `GET /api/v1/campaigns/{id}`.
    pub async fn campaign(&self, id: i64) -> Result<CampaignView, CallError> {
        self.json(self.request(reqwest::Method::GET, &format!("/api/v1/campaigns/{id}")))
            .await
    }

    /// `GET /api/v1/campaigns/{id}/history`: every point.
    pub async fn history(&self, id: i64) -> Result<History, CallError> {
        self.json(self.request(
            reqwest::Method::GET,
            &format!("/api/v1/campaigns/{id}/history"),
        ))
        .await
    }

    /// An adaptive campaign's resolved stages (none for other campaigns).
    pub async fn stages(&self, id: i64) -> Result<tslg_api::AdaptiveStages, CallError> {
        self.json(self.request(
            reqwest::Method::GET,
            &format!("/api/v1/campaigns/{id}/stages"),
        ))
        .await
    }

    /// Where the campaign's wall time went, in `buckets` buckets.
    pub async fn timeline(
        &self,
        id: i64,
        buckets: u32,
    ) -> Result<tslg_api::CampaignTimeline, CallError> {
        self.json(self.request(
            reqwest::Method::GET,
            &format!("/api/v1/campaigns/{id}/timeline?buckets={buckets}"),
        ))
        .await
    }

    /// At most `points` of the history, spaced logarithmically in tests.
    pub async fn history_points(&self, id: i64, points: usize) -> Result<History, CallError> {
        self.json(self.request(
            reqwest::Method::GET,
            &format!("/api/v1/campaigns/{id}/history?points={points}"),
        ))
        .await
    }

    /// A page of the campaign's events: those after test index `after`
    /// (from the first when `None`), at most `limit`.
    pub async fn events(
        &self,
        id: i64,
        after: Option<u64>,
        limit: usize,
    ) -> Result<tslg_api::EventPage, CallError> {
        let after = after.map_or(String::new(), |a| format!("&after={a}"));
        self.json(self.request(
            reqwest::Method::GET,
            &format!("/api/v1/campaigns/{id}/events?limit={limit}{after}"),
        ))
        .await
    }

    /// Test `index` of the campaign as an OpenSCENARIO file.
    pub async fn openscenario(&self, id: i64, index: u64) -> Result<String, CallError> {
        self.send(self.request(
            reqwest::Method::GET,
            &format!("/api/v1/campaigns/{id}/tests/{index}/openscenario"),
        ))
        .await?
        .text()
        .await
        .map_err(|e| CallError::Transient(format!("unreadable answer: {e}")))
    }

    /// The workers the coordinator has seen.
    pub async fn workers(&self) -> Result<tslg_api::WorkerList, CallError> {
        self.json(self.request(reqwest::Method::GET, "/api/v1/workers"))
            .await
    }

    /// `GET /api/v1/queue`: the workers the running campaigns want.
    pub async fn queue(&self) -> Result<tslg_api::QueueView, CallError> {
        self.json(self.request(reqwest::Method::GET, "/api/v1/queue"))
            .await
    }

    /// `POST /api/v1/campaigns/{id}/cancel`.
    pub async fn cancel_campaign(&self, id: i64) -> Result<CampaignView, CallError> {
        self.post(
            &format!("/api/v1/campaigns/{id}/cancel"),
            &serde_json::json!({}),
        )
        .await
    }

    /// `DELETE /api/v1/campaigns/{id}`: a stopped campaign and its records.
    pub async fn delete_campaign(&self, id: i64) -> Result<(), CallError> {
        self.send(self.request(reqwest::Method::DELETE, &format!("/api/v1/campaigns/{id}")))
            .await
            .map(|_| ())
    }

    /// `DELETE /api/v1/libraries/{id}`: a library no campaign uses.
    pub async fn delete_library(&self, id: i64) -> Result<(), CallError> {
        self.send(self.request(reqwest::Method::DELETE, &format!("/api/v1/libraries/{id}")))
            .await
            .map(|_| ())
    }
}
