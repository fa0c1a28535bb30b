//! The sphere preview end to end: `GET /fits/{id}/preview.png` on the daemon's API (through
//! the same router as every other request), `brdfd show SCAN --preview DIR`, and `brdfd render
//! --input FILE`; each answer is a PNG of the documented size.

#![allow(clippy::await_holding_lock)]

mod common;

use common::*;

/// Width and height of a PNG.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let reader = decoder.read_info().expect("a PNG");
    let info = reader.info();
    (info.width, info.height)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_api_and_show_draw_each_finished_fit() {
    let _serial = serial();
    bounded(async {
        let d = start_builtin(strict_fast()).await;
        let (api, client, token_file) = start_api(&d.service, d.dir.path()).await;
        let addr = api.local_addr();
        measure_reference(&d.service).await;
        let sample = mock_devices::recordings::samples()[0].sample.unwrap();
        let scan = scan_and_settle(&d.service, sample).await;
        let fits = d.store.fits_for_scan(scan).await.unwrap();
        assert_eq!(fits.len(), 3);
        let fit = fits[0].id;

        let (png, missing, bad) = tokio::task::spawn_blocking(move || {
            (
                client.get_bytes(&format!("/fits/{fit}/preview.png")),
                client.get_bytes("/fits/9999/preview.png").unwrap_err(),
                client.get_bytes("/fits/x/preview.png").unwrap_err(),
            )
        })
        .await
        .unwrap();
        let png = png.unwrap();
        // One sphere: the width is set by the 14 swatches, the height by the sphere.
        assert_eq!(png_size(&png), (844, 516));
        assert!(missing.to_string().contains("9999"), "{missing}");
        assert!(bad.to_string().contains("not a fit id"), "{bad}");

        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().to_str().unwrap().to_string();
        let addr_arg = addr.to_string();
        let scan_arg = scan.to_string();
        let token_arg = token_file.display().to_string();
        let show = tokio::task::spawn_blocking(move || {
            run_brdfd(
                &[
                    "show",
                    &scan_arg,
                    "--addr",
                    &addr_arg,
                    "--token-file",
                    &token_arg,
                    "--preview",
                    &out,
                ],
                None,
            )
        })
        .await
        .unwrap();
        assert!(
            show.status.success(),
            "{}",
            String::from_utf8_lossy(&show.stderr)
        );
        let mut written: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        written.sort();
        assert_eq!(written.len(), 3, "{written:?}");
        assert!(
            written.iter().any(|n| n.ends_with("-cf2.png")),
            "{written:?}"
        );
        for name in &written {
            let bytes = std::fs::read(dir.path().join(name)).unwrap();
            assert_eq!(png_size(&bytes), (844, 516), "{name}");
        }
        api.stop(std::time::Duration::from_secs(5)).await;
        d.service.shutdown().await;
    })
    .await;
}

#[test]
fn render_fits_a_scan_file_and_draws_the_cost_functions_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s.png");
    let input = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/t-freesia-pink.scan.json"
    );
    let o = run_brdfd(
        &[
            "render",
            "--input",
            input,
            "--cost",
            "cf1,cf2",
            "--out",
            out.to_str().unwrap(),
        ],
        None,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("2 sphere(s) (cf1, cf2), relative-to-tile"),
        "{stdout}"
    );
    // Two spheres side by side, plus margins: 2·20 + 2·256 + 20 = 572 < the swatch row (844).
    assert_eq!(png_size(&std::fs::read(&out).unwrap()), (844, 516));
    let o = run_brdfd(&["render", "--out", out.to_str().unwrap()], None);
    assert!(!o.status.success());
}
