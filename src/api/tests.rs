//! Unit tests of the API's error mapping; the routes are tested with real requests in
//! `tests/daemon_http.rs`.

use super::*;
use crate::store::ScanState;

#[test]
fn each_refusal_has_its_status_code_and_a_json_message() {
    let cases = [
        (
            ServiceError::Busy {
                operation: "scan 2".into(),
                seconds: 1.0,
            },
            409,
        ),
        (ServiceError::NoReference, 409),
        (ServiceError::Idle, 409),
        (
            ServiceError::NotComplete {
                scan: ScanId(1),
                state: ScanState::Failed,
                action: "exporting it",
            },
            409,
        ),
        (ServiceError::ShuttingDown, 503),
        (ServiceError::BadRequest("x".into()), 400),
        (
            ServiceError::Store(StoreError::NotFound {
                what: "scan",
                id: 5,
            }),
            404,
        ),
        (
            ServiceError::Store(StoreError::ScanState {
                scan: ScanId(1),
                state: ScanState::Complete,
                expected: "measuring",
                action: "abort it",
            }),
            409,
        ),
    ];
    for (e, code) in cases {
        let message = e.to_string();
        let api = ApiError(e);
        assert_eq!(api.status().as_u16(), code, "{message}");
    }
    let body =
        serde_json::to_value(ErrorBody::message("scan 5 does not exist in the store")).unwrap();
    assert_eq!(body["error"], "scan 5 does not exist in the store");
}
