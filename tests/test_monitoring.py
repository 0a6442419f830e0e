"""Zenoh monitoring between two sessions on loopback (explicit endpoints, no multicast)."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import pytest

from companion.monitoring import MonitorConfig, MonitorPublisher, MonitorWatcher, vehicle_of


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def pair() -> Iterator[tuple[MonitorPublisher, MonitorWatcher]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    pub = MonitorPublisher(
        MonitorConfig(listen=(endpoint,)), "v1",
        providers={"config": lambda: {"vehicle": "v1"}, "landmarks": lambda: [{"id": "a"}]},
    )
    watcher = MonitorWatcher(MonitorConfig(connect=(endpoint,)))
    time.sleep(0.3)  # let the peers connect and declare interests
    yield pub, watcher
    watcher.close()
    pub.close()


def test_published_json_and_preview_reach_the_watcher(
    pair: tuple[MonitorPublisher, MonitorWatcher],
) -> None:
    pub, watcher = pair
    pub.publish_json("status", {"state": "tracking", "fps": 30.0})
    pub.publish_json("events", {"event": "link-up"})
    pub.publish_json("events", {"event": "acquired", "landmark": "a"})
    assert pub.publish_preview(b"\xff\xd8jpeg", now_s=100.0)
    assert watcher.wait_for("preview", timeout_s=5.0)
    assert watcher.wait_for("status", timeout_s=5.0)
    view = watcher.snapshot().vehicles["v1"]
    assert view.latest["status"] == {"state": "tracking", "fps": 30.0}
    assert [e["event"] for e in view.events] == ["link-up", "acquired"]
    assert view.preview_jpeg == b"\xff\xd8jpeg"
    age = view.age_s("status")
    assert age is not None and 0.0 <= age < 5.0
    assert view.age_s("pose") is None


def test_preview_is_rate_limited() -> None:
    pub = MonitorPublisher(MonitorConfig(preview_rate_hz=2.0), "v2")
    try:
        assert pub.publish_preview(b"a", now_s=10.0)
        assert not pub.publish_preview(b"b", now_s=10.2)
        assert pub.publish_preview(b"c", now_s=10.51)
        assert pub.published["preview"] == 2
    finally:
        pub.close()


def test_queryables_answer_config_and_landmarks(
    pair: tuple[MonitorPublisher, MonitorWatcher],
) -> None:
    _, watcher = pair
    assert watcher.query("v1", "config") == {"vehicle": "v1"}
    assert watcher.query("v1", "landmarks") == [{"id": "a"}]
    assert watcher.query("nobody", "config", timeout_s=0.5) is None


@pytest.mark.parametrize(
    ("key", "expected"),
    [("companion/v1/status", ("v1", "status")), ("companion/v1", None),
     ("other/v1/status", None), ("companion/a/b/c", None)],
)
def test_vehicle_of(key: str, expected: tuple[str, str] | None) -> None:
    assert vehicle_of(key) == expected


def test_client_mode_without_a_router_is_a_one_line_link_error() -> None:
    from companion.errors import LinkError

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with pytest.raises(LinkError) as info:
        MonitorPublisher(MonitorConfig(mode="client", connect=(endpoint,)), "v1")
    assert str(info.value).startswith(f"zenoh (client, {endpoint}): Unable to connect")
    assert "\n" not in str(info.value)


def test_preview_is_wanted_only_while_someone_subscribes(
    pair: tuple[MonitorPublisher, MonitorWatcher],
) -> None:
    """A preview nobody watches is not drawn (issue 23: its encoding costs the frame's core)."""
    pub, _watcher = pair
    assert pub.preview_wanted(now_s=100.0)  # the watcher subscribes to every topic
    assert pub.publish_preview(b"a", now_s=100.0)
    assert not pub.preview_wanted(now_s=100.2)  # not due yet
    alone = MonitorPublisher(MonitorConfig(listen=(f"tcp/127.0.0.1:{free_port()}",)), "v3")
    try:
        assert alone.preview_due(now_s=100.0)
        assert not alone.preview_wanted(now_s=100.0)
    finally:
        alone.close()
