//! Processor in the loop: the `pil` firmware image under QEMU (Cortex-M4F, mps2-an386) closes the
//! loop on `reach` with the checked-in student and must equal the host int8 policy (the blob of
//! the same export) bit for bit, chunk by chunk and episode by episode; its frame checks answer
//! bad frames with ERROR replies and keep serving.
//!
//! Skipped with a message when QEMU or the Cortex-M toolchain is missing, failing instead when
//! `FRMD_REQUIRE_QEMU` is set (`frmd_firmware_support::host::qemu::available`).
use frmd_firmware_support::host::qemu;
use frmd_firmware_support::host::student::student;
use frmd_firmware_support::pil::{ErrorCode, MsgType};
use frmd_host::eval::{run_episodes, EvalConfig};
use frmd_host::firmware::link::frame;
use frmd_host::firmware::lockstep::Lockstep;
use frmd_host::firmware::policy::FirmwarePolicy;
use frmd_host::firmware::{build, default_repo};
use frmd_host::policy::int8::Int8Policy;

const EPISODES: usize = 4;

fn host_policy() -> Int8Policy {
    let blob = student().blob().expect("blob of the checked-in student");
    Int8Policy::from_blob(&blob, "int8").expect("host int8 policy")
}

#[test]
fn firmware_closes_the_loop_bit_for_bit_with_the_host_policy() {
    let repo = default_repo();
    if !qemu::available(
        "firmware_closes_the_loop_bit_for_bit_with_the_host_policy",
        &repo,
    ) {
        return;
    }
    let image =
        build(&repo, frmd_host::firmware::Board::M4, None).expect("build the pil image for m4");
    let firmware = FirmwarePolicy::start(&image).expect("boot the pil image");
    let host = host_policy();
    let dims = host.dims();
    let info = firmware.info().clone();
    assert_eq!(
        (info.history, info.obs_dim, info.action_dim, info.horizon),
        (dims.history, dims.obs_dim, dims.action_dim, dims.horizon),
        "the image's policy sizes differ from the host blob's"
    );
    let cfg = EvalConfig {
        episodes: EPISODES,
        history: info.history,
        warmup_calls: 1,
        ..EvalConfig::default()
    };

    let mut lockstep = Lockstep::new(firmware, host);
    let through_firmware =
        run_episodes("reach", &mut lockstep, &cfg).expect("closed loop through the firmware");
    let count = lockstep.count.clone();
    assert!(count.chunks > EPISODES, "too few chunks: {count:?}");
    assert_eq!(
        count.differing_chunks, 0,
        "firmware chunks differ from the host int8 policy's: {count:?}"
    );

    let through_host =
        run_episodes("reach", &mut host_policy(), &cfg).expect("closed loop on the host");
    let outcome = |r: &frmd_host::eval::EvalReport| {
        r.per_episode
            .iter()
            .map(|e| (e.seed, e.success, e.failed, e.length))
            .collect::<Vec<_>>()
    };
    assert_eq!(
        outcome(&through_firmware),
        outcome(&through_host),
        "episodes differ"
    );
    assert_eq!(through_firmware.successes, through_host.successes);

    let stats = lockstep.lead.stats();
    eprintln!(
        "pil m4: {} chunks, Policy::act {}..{} instructions (mean {:.1}), {}/{} successes, median {:.0} us per chunk through QEMU",
        stats.chunks, stats.act_min, stats.act_max, stats.act_mean, through_firmware.successes, EPISODES, through_firmware.latency_us_median
    );
    assert_eq!(stats.chunks, count.chunks);
    // One SysTick tick is 40 instructions: a chunk of constant length reads as n or n + 1 ticks.
    assert!(
        stats.act_max - stats.act_min <= 40,
        "chunk instruction count varies: {stats:?}"
    );
    assert!(stats.act_min > 0);

    let mut firmware = lockstep.lead;
    check_bad_frames(&mut firmware);
    firmware.close().expect("EXIT");
}

/// Every malformed request gets an ERROR reply with its code, and the image serves on.
fn check_bad_frames(firmware: &mut FirmwarePolicy) {
    let link = firmware.link();
    let mut expect_error = |bytes: &[u8], code: ErrorCode| {
        link.send_raw(bytes).expect("send");
        let reply = link.receive("a bad frame").expect("a reply to a bad frame");
        let error = reply
            .as_error()
            .unwrap_or_else(|| panic!("expected ERROR {code:?}, got {reply:?}"));
        assert_eq!(error.code, Some(code), "{error:?}");
    };
    expect_error(b"XY\x01\x00\x00\x00\x00\x00\x00\x00", ErrorCode::BadMagic);
    let mut corrupted = frame(MsgType::Hello as u8, &[]).unwrap();
    *corrupted.last_mut().unwrap() ^= 0x55;
    expect_error(&corrupted, ErrorCode::BadCrc);
    expect_error(
        &frame(MsgType::Act as u8, &[1, 2, 3]).unwrap(),
        ErrorCode::BadLength,
    );
    expect_error(&frame(0x42, &[]).unwrap(), ErrorCode::UnknownType);
    expect_error(b"FP\x03\x00\xff\xff", ErrorCode::TooLong);
    let reply = link
        .request(MsgType::Hello, &[])
        .expect("HELLO after bad frames");
    assert_eq!(reply.msg_type, MsgType::Info);
}
