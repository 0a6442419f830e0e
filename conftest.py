"""Fixtures for every test directory."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def _root_logger_restored() -> Iterator[None]:
    """A test that runs ``companion.cli.main`` in-process configures the root logger
    (``setup_logging``: its handler and level, e.g. ``--log-level error``); put it back so
    that the next test's ``caplog`` sees what it logs."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield
    for handler in list(root.handlers):
        if handler not in handlers:
            root.removeHandler(handler)
    for handler in handlers:
        if handler not in root.handlers:
            root.addHandler(handler)
    root.setLevel(level)


#: The slow tests, by node id prefix (a file, or a test with all its parameters). Marked
#: ``slow`` at collection, so that ``pytest -m "not slow"`` is the fast suite a developer
#: runs alone (under a minute; docs/testing.md) while CI runs everything. Chosen by
#: measurement (``pytest --durations=0``): every test over 0.5 s of setup + call + teardown
#: on the shared machine, and all of sitl_tests/ (whole-program flights against the fake
#: autopilot). A new test that takes longer belongs here (or marked ``@pytest.mark.slow``).
SLOW: tuple[str, ...] = (
    "sitl_tests/",
    "tests/test_run_map.py",
    "tests/tracker/test_tracker_regression.py",
    "tests/test_run_recorded.py",
    "tests/test_replay.py",
    "tests/test_wheel.py",
    "tests/calibration/test_calibrate.py",
    "tests/calibration/test_live.py",
    "tests/dashboard/test_dashboard.py",
    "tests/detector/test_accuracy.py",
    "tests/follow/test_follow_equivalence.py",
    "tests/landmarks/test_landmarks_cli.py",
    "tests/mavlink/test_autopilot_setup.py",
    "tests/mavlink/test_fake_autopilot_cli.py",
    "tests/pose/test_attitude_loop.py",
    "tests/sources/test_commands.py",
    "tests/test_demo.py",
    "tests/test_demo_visible.py",
    "tests/test_dev_script.py",
    "tests/test_monitor_cli.py",
    "tests/test_real_photo_landmark.py",
    "tests/test_replay_telemetry.py",
    "tests/calibration/test_check.py::test_a_flight_with_the_shipped_noise_says_uncalibrated",
    "tests/calibration/test_check.py::test_a_good_set_up_passes",
    "tests/calibration/test_check.py::test_a_wrong_camera_file_fails_on_that_line",
    "tests/calibration/test_check.py::test_an_autopilot_not_set_up_fails_parameters_and_a_missing_stream_fails_streams",
    "tests/calibration/test_check.py::test_intrinsics_of_another_resolution_fail",
    "tests/calibration/test_check.py::test_landmarks_the_matcher_cannot_find_fail",
    "tests/calibration/test_check.py::test_no_autopilot_and_the_wrong_autopilot_fail_the_link",
    "tests/calibration/test_noise.py::test_a_landmark_not_seen_is_one_line_and_writes_nothing",
    "tests/calibration/test_noise.py::test_the_measured_jitter_is_the_added_one",
    "tests/calibration/test_noise.py::test_the_value_written_undoes_the_perceptions_plate_size_law",
    "tests/detector/test_detector.py::test_detects_a_simulated_landmark_in_a_640x480_frame",
    "tests/follow/test_follow_truth.py::test_a_vehicle_without_truth_is_a_one_line_error_naming_the_message",
    "tests/follow/test_follow_truth.py::test_rendered_pose_follows_the_simulators_truth",
    "tests/follow/test_follow_truth.py::test_simstate_alone_is_refused_because_it_has_no_altitude",
    "tests/follow/test_follow_truth.py::test_stale_truth_stops_the_frames_until_it_comes_back",
    "tests/follow/test_run_follow.py::test_companion_run_with_the_sitl_config_closes_the_loop",
    "tests/follow/test_run_follow.py::test_fly_sets_the_mode_and_arms_when_disarmed",
    "tests/follow/test_run_follow.py::test_fly_square_commands_and_position_targets",
    "tests/follow/test_run_follow.py::test_without_the_truth_message_run_fails_with_one_line",
    "tests/landmarks/test_landmarks_postgis.py::test_bad_import_leaves_repository_unchanged",
    "tests/landmarks/test_landmarks_postgis.py::test_import_get_and_round_trip_match_sqlite",
    "tests/landmarks/test_landmarks_postgis.py::test_sync_pulls_the_practical_map_into_sqlite",
    "tests/landmarks/test_landmarks_postgis.py::test_update_scores",
    "tests/landmarks/test_landmarks_selection.py::test_reasons_match_a_brute_force_greedy_oracle",
    "tests/landmarks/test_landmarks_store.py::test_failure_late_in_import_rolls_back_everything",
    "tests/landmarks/test_landmarks_store.py::test_killed_import_leaves_database_exactly_as_it_was",
    "tests/landmarks/test_landmarks_store.py::test_onboard_database_is_seeded_from_the_configured_map_once",
    "tests/mavlink/test_bad_input.py::test_a_10k_per_second_flood_does_not_stall_the_heartbeat",
    "tests/mavlink/test_bad_input.py::test_codec_feed_never_raises_and_accounts_for_every_byte",
    "tests/mavlink/test_fake_drift.py::test_error_has_the_stated_sigma_and_correlation_time",
    "tests/mavlink/test_fake_drift.py::test_the_default_is_a_real_ekfs_error_with_a_slow_yaw_drift",
    "tests/mavlink/test_faults_signing.py::test_corrupted_bytes_from_the_autopilot_are_counted_not_fatal",
    "tests/mavlink/test_faults_signing.py::test_latency_jitter_and_loss_are_survived_and_counted",
    "tests/mavlink/test_faults_signing.py::test_link_drop_is_detected_and_recovered",
    "tests/mavlink/test_faults_signing.py::test_reboot_is_detected_and_the_origin_is_set_again",
    "tests/mavlink/test_link_faults.py::test_a_refused_tcp_connection_is_retried_until_the_autopilot_listens",
    "tests/mavlink/test_loopback.py::test_ardupilot_odometry_is_fused_at_the_configured_rate",
    "tests/mavlink/test_loopback.py::test_fake_enforces_frames_mocap_and_spacing",
    "tests/mavlink/test_loopback.py::test_heartbeat_status_follows_application_health",
    "tests/mavlink/test_loopback.py::test_origin_is_retried_through_failures_until_the_position_shows_it",
    "tests/mavlink/test_loopback.py::test_px4_odometry_local_ned_vision_with_timesync",
    "tests/mavlink/test_loopback.py::test_telemetry_cache_and_generator_follow_the_vehicle",
    "tests/mavlink/test_mavsdk_backend.py::test_mavsdk_ardupilot_odometry_frames_20_12_fused_and_origin_set",
    "tests/mavlink/test_mavsdk_backend.py::test_mavsdk_link_drop_and_reboot_are_handled",
    "tests/mavlink/test_mavsdk_backend.py::test_mavsdk_px4_vpe_with_timesync_and_landing_target",
    "tests/mavlink/test_mavsdk_backend.py::test_mavsdk_without_autopilot_fails_with_one_line",
    "tests/mavlink/test_peers.py::test_mavproxy_routes_and_parses_the_companions_messages",
    "tests/mavlink/test_transports.py::test_tcp_client_reconnects_when_the_autopilot_comes_back",
    "tests/pose/test_covariance.py::test_a_plates_common_scale_error_is_in_its_covariance",
    "tests/pose/test_covariance.py::test_bearing_ls_position_nees_is_chi_square_3",
    "tests/pose/test_covariance.py::test_one_plates_outline_error_is_in_its_covariance",
    "tests/pose/test_scenarios.py::test_head_on_wall_without_attitude_is_consistent",
    "tests/pose/test_scenarios.py::test_misnamed_detections_are_dropped_not_believed",
    "tests/pose/test_scenarios.py::test_multi_landmark_rmse_is_within_half_a_percent_of_distance",
    "tests/sim/test_realworld.py::test_each_seed_is_another_world",
    "tests/sim/test_realworld.py::test_the_light_ramps_down_steps_up_and_turns_warm",
    "tests/sim/test_realworld.py::test_the_world_is_real_photographs_with_truth_and_appearance_images",
    "tests/sim/test_render_truth.py::test_truth_matches_pixels_for_random_poses",
    "tests/sim/test_render_truth.py::test_truth_with_lens_distortion",
    "tests/sim/test_scenarios.py::test_any_pose_renders_without_error",
    "tests/sim/test_scenarios.py::test_sim_source_in_its_own_process_renders_the_same_frames",
    "tests/test_cli.py::test_a_missing_extra_is_one_line_naming_it",
    "tests/test_cli.py::test_config_json_names_the_layer_that_set_each_key",
    "tests/test_cli.py::test_config_json_shows_overrides_and_files",
    "tests/test_cli.py::test_help_lists_the_commands_that_exist",
    "tests/test_cli.py::test_native_thread_pools_are_one_thread_unless_the_user_says_otherwise",
    "tests/test_cli.py::test_no_command_prints_help_and_fails",
    "tests/test_cli.py::test_relative_config_path_is_shown_as_given",
    "tests/test_cli.py::test_unknown_key_is_one_line_exit_2",
    "tests/test_cli.py::test_version",
    "tests/test_cli.py::test_wrong_type_is_one_line_exit_2_no_traceback",
    "tests/test_faults_cli.py::test_a_frame_source_that_fails_for_good_exits_1",
    "tests/test_faults_cli.py::test_a_full_disk_during_import_is_one_line_and_leaves_the_database_as_it_was",
    "tests/test_faults_cli.py::test_a_port_in_use_is_one_line_and_status_1",
    "tests/test_faults_cli.py::test_sigterm_during_a_plain_command_unwinds_and_exits_143",
    "tests/test_flightlog.py::test_cli_show_and_export",
    "tests/test_flightlog.py::test_killed_writer_loses_nothing_it_logged",
    "tests/test_flightlog_faults.py::test_a_flight_goes_on_with_fixes_when_the_disk_fills_and_stops_when_asked",
    "tests/test_flightlog_faults.py::test_a_full_disk_stops_the_log_with_one_warning_and_close_does_not_raise",
    "tests/test_flightlog_faults.py::test_ctrl_c_ends_the_demo_with_130_and_fps_over_the_time_flown",
    "tests/test_monitoring.py::test_preview_is_wanted_only_while_someone_subscribes",
    "tests/test_monitoring.py::test_published_json_and_preview_reach_the_watcher",
    "tests/test_monitoring.py::test_queryables_answer_config_and_landmarks",
    "tests/test_perception.py::test_a_detector_hit_restarts_a_track_when_the_reference_aligns_there",
    "tests/test_perception.py::test_a_plate_at_the_edge_of_a_rectified_frame_carries_a_larger_corner_sigma",
    "tests/test_perception.py::test_a_wrong_attitude_is_rejected_with_an_event_and_the_fixes_stay_true",
    "tests/test_perception.py::test_acquisition_never_invents_a_landmark",
    "tests/test_perception.py::test_an_over_exposed_plates_corners_are_not_used",
    "tests/test_perception.py::test_housekeeping_sees_rectified_frames_even_ones_process_let_go",
    "tests/test_perception.py::test_no_track_for_a_landmark_out_of_view",
    "tests/test_perception.py::test_small_plates_corners_carry_a_larger_sigma",
    "tests/test_perception.py::test_survey_fixes_match_the_truth_and_say_how_good_they_are",
    "tests/test_perception.py::test_the_committed_detector_starts_tracks_on_the_right_landmarks",
    "tests/test_perception.py::test_with_tracks_running_housekeeping_takes_one_heavy_step_per_call",
    "tests/test_vehicle_example.py::test_run_with_the_example_sends_fixes_the_autopilot_accepts",
    "tests/tracker/test_tracker_adaptive.py::test_follows_a_moving_sign",
    "tests/tracker/test_tracker_adaptive.py::test_grayscale_input_uses_the_grey_features",
    "tests/tracker/test_tracker_adaptive.py::test_rank_phase_shifts_the_periodic_reranking",
    "tests/tracker/test_tracker_adaptive.py::test_reports_lost_while_hidden_and_reacquires",
    "tests/tracker/test_tracker_adaptive.py::test_same_seed_same_track_and_no_global_random_state",
    "tests/tracker/test_tracker_baselines.py::test_baseline_follows_the_sign",
    "tests/tracker/test_tracker_eval.py::test_eval_writes_table_json_and_report",
    "tests/tracker/test_tracker_eval.py::test_recorded_stream_truth_follows_one_landmark",
    "tests/tracker/test_tracker_refine.py::test_box_follows_a_change_of_aspect",
    "tests/tracker/test_tracker_refine.py::test_box_follows_a_growing_target_in_colour_and_grey",
    # over 0.6 s each in the fast suite's --durations of 2026-12-07 (69.5 s in all)
    "tests/acquire/test_cut_match.py::test_a_leaving_plate_is_held_from_the_shift_of_the_frame_around_it",
    "tests/acquire/test_edge_align.py::test_a_cut_plate_holds_its_corners_where_a_full_alignment_bends_them",
    "tests/follow/test_follow_truth.py::test_a_companion_that_falls_behind_gets_the_frame_due_now",
    "tests/pose/test_covariance.py::test_one_plates_tilt_error_is_in_its_covariance",
    "tests/pose/test_covariance.py::test_plates_whose_corners_err_together_are_stated_so",
    "tests/pose/test_echo.py::test_exact_pixels_spread_as_the_autopilots_part_says",
    "tests/sim/test_scenarios.py::test_frames_come_through_the_pipe_where_no_shared_memory_may_be_made",
    "tests/sim/test_scenarios.py::test_frames_from_the_rendering_process_are_the_companions_own",
    "tests/test_demo_autopilot.py::test_the_fake_autopilot_flies_in_its_own_process_and_reports",
    "tests/test_fly_watch.py::test_fly_keeps_flying_while_nothing_changes",
    "tests/test_import_layers.py::test_no_module_is_loaded_by_its_path",
    "tests/test_import_layers.py::test_the_run_process_does_not_load_the_simulator",
    "tests/test_keepup.py::test_the_app_warns_when_its_worker_falls_behind",
    "tests/test_lone_plate.py::test_aligning_on_the_feature_mixed_with_grey_levels_removes_the_keystone",
    "tests/test_lone_plate.py::test_leaving_the_plates_outer_ring_out_of_the_alignment_shrinks_its_keystone",
    "tests/test_lone_plate.py::test_lone_plate_fix_is_honest_and_close",
    "tests/test_partial_box.py::test_a_plate_coming_into_view_keeps_its_corners_and_its_tracker_is_reseated",
    "tests/test_perception_schedule.py::test_appearance_checks_run_on_the_thread_that_updated_the_track",
    "tests/test_perception_schedule.py::test_the_tracks_appearance_checks_are_spread_over_the_frames",
    "tests/test_replay_clock.py::test_fast_replay_is_on_the_recordings_clock_whatever_the_load",
    "tests/test_track_coast.py::test_coasting_keeps_the_corners_and_runs_a_third_of_the_updates",
)


def is_slow(nodeid: str) -> bool:
    """Whether :data:`SLOW` lists the test (its folder, its file or the test itself)."""
    node = nodeid.split("[", 1)[0]  # every parameter set of a listed test
    path = node.split("::", 1)[0]
    return node in SLOW or path in SLOW or any(
        path.startswith(folder) for folder in SLOW if folder.endswith("/"))


#: The whole-program flights in real time (node id prefixes: a folder, a file or a test with
#: all its parameters; each also ``slow``): they wait on the clock far more than they use a
#: core, 16 of CI's 28 minutes one after the other.  Marked ``realtime``: ``python3 dev.py
#: test`` runs them, still one after the other, in a second pytest beside the rest of the
#: suite (docs/testing.md, "CI's budget").  All of sitl_tests/: with only the long ones
#: there, a short flight judged on its timing (the longest gap between fixes while bytes
#: are corrupted: 1.07 s against 1 s) ran beside a long one and failed once in five.
REALTIME: tuple[str, ...] = ("sitl_tests/",)


#: The real-time flights that ``python3 dev.py test`` flies first, with nothing beside them
#: (node id prefixes, as :data:`REALTIME`; marked ``alone``): the strict square, whose
#: bounds (the longest gap between fused fixes 1 s, the autopilot's estimate within 0.5 m)
#: are on timing.  Beside the rest it failed 1 to 3 of its 5 seeds in clean-clone CI runs,
#: alone none of ten (docs/testing.md, "The square flies alone").
ALONE: tuple[str, ...] = ("sitl_tests/test_fly_strict.py::test_three_laps_against_the_strict_fake",)


def listed(nodeid: str, prefixes: tuple[str, ...]) -> bool:
    """Whether ``prefixes`` list the test (its folder, its file, or the test with all its
    parameters)."""
    node = nodeid.split("[", 1)[0]
    return any(node == p or node.startswith(p if p.endswith("/") else p + "::")
               for p in prefixes)


def is_realtime(nodeid: str) -> bool:
    """Whether :data:`REALTIME` lists the test."""
    return listed(nodeid, REALTIME)


def is_alone(nodeid: str) -> bool:
    """Whether :data:`ALONE` lists the test."""
    return listed(nodeid, ALONE)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the tests listed in :data:`SLOW` ``slow``, those in :data:`REALTIME` also
    ``realtime``, those in :data:`ALONE` also ``alone``."""
    for item in items:
        if is_slow(item.nodeid):
            item.add_marker(pytest.mark.slow)
        if is_realtime(item.nodeid):
            item.add_marker(pytest.mark.realtime)
        if is_alone(item.nodeid):
            item.add_marker(pytest.mark.alone)
