"""Capture from a camera (rtloop.acquisition.capture) with a fake camera: the machines have none.

FakeCamera behaves like cv2.VideoCapture: read() gives noisy frames of a fixed picture, get()/set()
work on a table of properties, and only the properties it is told to support accept a set(). While
its automatic exposure is on, the picture brightens frame by frame (auto-exposure hunting), so a lock
that does not take shows up as drift.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

import rtloop.acquisition.capture as capture_module
from rtloop.acquisition import AcquisitionError, capture_photo, save_capture
from rtloop.cli.acquire import acquire_main

H, W = 48, 64


class FakeCamera:
    def __init__(
        self,
        supported=None,
        noise: float = 6.0,
        depth: int = 8,
        hunting: float = 0.0,
        fail_after: int | None = None,
        confirm: bool = True,
    ):
        rng = np.random.default_rng(0)
        full = 255 if depth == 8 else 65535
        self.base = rng.uniform(0.1 * full, 0.8 * full, (H, W, 3))
        self.full, self.dtype = full, (np.uint8 if depth == 8 else np.uint16)
        self.noise = noise * full / 255
        self.rng = np.random.default_rng(1)
        self.props = {
            cv2.CAP_PROP_FRAME_WIDTH: W,
            cv2.CAP_PROP_FRAME_HEIGHT: H,
            cv2.CAP_PROP_FPS: 30.0,
            cv2.CAP_PROP_AUTO_EXPOSURE: 3.0,
            cv2.CAP_PROP_EXPOSURE: 156.0,
            cv2.CAP_PROP_AUTO_WB: 1.0,
            cv2.CAP_PROP_WB_TEMPERATURE: 4600.0,
            cv2.CAP_PROP_GAIN: 0.0,
        }
        self.supported = set(self.props) if supported is None else set(supported)
        self.hunting = hunting
        self.fail_after = fail_after
        self.confirm = confirm
        self.frames_read = 0
        self.released = False

    def isOpened(self) -> bool:
        return True

    def read(self):
        self.frames_read += 1
        if self.fail_after is not None and self.frames_read > self.fail_after:
            return False, None
        gain = 1.0
        if self.props[cv2.CAP_PROP_AUTO_EXPOSURE] != 1.0:
            gain += self.hunting * self.frames_read
        frame = self.base * gain + self.rng.normal(0, self.noise, self.base.shape)
        return True, np.clip(np.round(frame), 0, self.full).astype(self.dtype)

    def get(self, prop: int) -> float:
        return float(self.props.get(prop, 0.0))

    def set(self, prop: int, value: float) -> bool:
        if prop not in self.supported:
            return False
        if self.confirm:
            self.props[prop] = float(value)
        return True

    def release(self) -> None:
        self.released = True


def test_average_locks_and_report() -> None:
    cam = FakeCamera()
    result = capture_photo(cam, frames=16, warmup=5)
    assert result.image.dtype == np.uint16 and result.image.shape == (H, W, 3)
    # Averaging cuts the noise by about sqrt(16) = 4: compare with the noiseless picture.
    err_avg = np.abs(result.image / 257.0 - cam.base).mean()
    err_one = 6.0 * np.sqrt(2 / np.pi)  # mean |N(0, 6)|
    assert err_avg < err_one / 3
    s = result.settings
    assert s["locks"]["exposure"]["state"] == "locked"
    assert s["locks"]["white_balance"]["state"] == "locked"
    assert cam.props[cv2.CAP_PROP_AUTO_EXPOSURE] == 1.0  # V4L2's "manual"
    assert cam.props[cv2.CAP_PROP_EXPOSURE] == 156.0  # kept at the settled value
    assert cam.props[cv2.CAP_PROP_AUTO_WB] == 0.0
    assert s["frames_averaged"] == 16 and s["frame"] == {
        "width": W,
        "height": H,
        "channels": 3,
        "bits": 8,
        "order": "BGR",
    }
    assert s["properties"]["wb_temperature"] == 4600.0
    assert s["noise_per_frame_16bit"] == pytest.approx(6.0 * 257, rel=0.1)  # mean per-pixel std over frames
    assert s["noise_after_averaging_16bit"] == pytest.approx(s["noise_per_frame_16bit"] / 4)
    assert result.warnings == []
    assert cam.frames_read == 5 + 3 + 16  # warm-up, settling, averaged


def test_given_exposure_and_temperature_are_set() -> None:
    cam = FakeCamera()
    result = capture_photo(cam, frames=2, warmup=0, exposure=50, wb_temperature=5500)
    assert cam.props[cv2.CAP_PROP_EXPOSURE] == 50.0 and cam.props[cv2.CAP_PROP_WB_TEMPERATURE] == 5500.0
    assert result.settings["locks"]["exposure"]["exposure_read_back"] == 50.0


def test_backend_that_cannot_lock_is_reported_and_drift_is_caught() -> None:
    cam = FakeCamera(supported=[], hunting=0.004)
    messages = []
    result = capture_photo(cam, frames=8, warmup=2, log=messages.append)
    locks = result.settings["locks"]
    assert locks["exposure"]["state"] == "unsupported"
    assert locks["white_balance"]["state"] == "unsupported"
    text = "\n".join(result.warnings)
    assert "exposure: this camera/backend" in text and "white balance: this camera/backend" in text
    assert "brightness changed by" in text
    assert any(m.startswith("warning:") for m in messages)


def test_unconfirmed_lock_is_reported_as_requested() -> None:
    cam = FakeCamera(confirm=False)
    result = capture_photo(cam, frames=2, warmup=0)
    assert result.settings["locks"]["exposure"]["state"] == "requested"
    assert any("did not confirm" in w for w in result.warnings)


def test_16bit_frames_are_kept_16bit() -> None:
    cam = FakeCamera(depth=16, noise=2.0)
    result = capture_photo(cam, frames=4, warmup=0)
    assert result.settings["frame"]["bits"] == 16
    assert np.abs(result.image - cam.base).mean() < 257 * 2.0


def test_save_writes_16bit_png_and_json(tmp_path) -> None:
    result = capture_photo(FakeCamera(), frames=4, warmup=1)
    png, report = save_capture(result, tmp_path / "shot.png")
    back = cv2.imread(png, cv2.IMREAD_UNCHANGED)
    assert back.dtype == np.uint16 and np.array_equal(back, result.image)
    data = json.loads((tmp_path / "shot.json").read_text())
    assert report.endswith("shot.json") and data["image"] == "shot.png" and data["frames_averaged"] == 4
    with pytest.raises(AcquisitionError, match=r"ending in \.png"):
        save_capture(result, tmp_path / "shot.jpg")


def test_capture_failures_are_clear() -> None:
    with pytest.raises(AcquisitionError, match="could not read a frame"):
        capture_photo(FakeCamera(fail_after=3), frames=8, warmup=2)

    class Closed(FakeCamera):
        def isOpened(self) -> bool:
            return False

    with pytest.raises(AcquisitionError, match="not open"):
        capture_photo(Closed())

    class Resizing(FakeCamera):
        def read(self):
            ok, frame = super().read()
            return ok, frame if self.frames_read < 6 else frame[:-2]

    with pytest.raises(AcquisitionError, match="changed its mode"):
        capture_photo(Resizing(), frames=8, warmup=2, settle_frames=0)


def test_capture_command_with_a_fake_camera(tmp_path, monkeypatch, capsys) -> None:
    cams = []

    def fake_open(device, backend, width, height):
        assert device == 2 and backend == "v4l2" and (width, height) == (64, 48)
        cams.append(FakeCamera())
        return cams[-1]

    monkeypatch.setattr(capture_module, "open_camera", fake_open)
    out = tmp_path / "photo.png"
    code = acquire_main(
        [
            "capture",
            "--device",
            "2",
            "--backend",
            "v4l2",
            "--size",
            "64x48",
            "--frames",
            "4",
            "--warmup",
            "1",
            "--out",
            str(out),
        ]
    )
    stdout = capsys.readouterr().out
    assert code == 0 and out.is_file() and (tmp_path / "photo.json").is_file()
    assert "exposure locked" in stdout and cams[0].released


def test_capture_command_without_a_camera_fails_cleanly(tmp_path, capsys) -> None:
    code = acquire_main(
        ["capture", "--device", str(tmp_path / "no-such-video.avi"), "--out", str(tmp_path / "x.png")]
    )
    err = capsys.readouterr().err
    assert code == 1 and "cannot open it" in err and not (tmp_path / "x.png").exists()


def test_capture_command_through_real_videocapture_on_a_video_file(tmp_path, capsys) -> None:
    """OpenCV's own VideoCapture on a file: frames are read and averaged; a file has no exposure
    or white balance controls, and the report says so."""
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (W, H))
    if not writer.isOpened():
        pytest.skip("this OpenCV cannot write MJPG AVI files")
    for _ in range(20):
        writer.write(np.full((H, W, 3), (40, 120, 200), np.uint8))
    writer.release()
    out = tmp_path / "avg.png"
    code = acquire_main(
        ["capture", "--device", str(video), "--frames", "8", "--warmup", "2", "--out", str(out)]
    )
    captured = capsys.readouterr()
    assert code == 0
    image = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert image.dtype == np.uint16 and image.shape == (H, W, 3)
    assert np.allclose(image.reshape(-1, 3).mean(axis=0) / 257, (40, 120, 200), atol=4)
    report = json.loads((tmp_path / "avg.json").read_text())
    assert report["locks"]["exposure"]["state"] == "unsupported"
    assert "does not let OpenCV lock it" in captured.err
