"""The Python module against independent truth and against the command line.

Run by CTest (python/module) with PYTHONPATH at the build's python/ folder and PROCAM_BINARY,
PROCAM_SHARED_DIR set; `python3 -m pytest tests/python` with the same variables runs it by hand.
"""

import json
import os
import pathlib
import subprocess
import threading

import numpy as np
import pytest

import procam

BINARY = os.environ.get("PROCAM_BINARY", "procam")
SHARED = pathlib.Path(os.environ.get("PROCAM_SHARED_DIR", "../shared"))


def run_procam(*args):
    subprocess.run([BINARY, *map(str, args)], check=True, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def tiny_box():
    return procam.geometry("synthetic:tiny_box", patches=200)


def test_form_factors_obey_reciprocity_and_conservation(tiny_box):
    f = tiny_box.form_factors
    area = tiny_box.fine.area
    n = tiny_box.fine.size
    assert f.shape == (n, n)
    # Light leaving a patch lands somewhere at most once (rows sum to at most 1; the box is open,
    # so less), and A_i F_ij = A_j F_ji (reciprocity).
    assert np.all(f >= 0)
    assert np.all(f.sum(axis=1) <= 1.0 + 1e-9)
    assert np.all(np.diag(f) == 0)
    flux = area[:, None] * f
    assert np.allclose(flux, flux.T, rtol=0.05, atol=1e-6)
    # The view is read-only and shares the C++ object's memory.
    assert not f.flags.writeable
    assert tiny_box.fine.adjacency.shape[1] == 2
    assert np.all(tiny_box.fine.adjacency[:, 0] < tiny_box.fine.adjacency[:, 1])


def test_compensation_equals_the_command_line_bit_for_bit(tiny_box, tmp_path):
    run_procam("compensate", "synthetic:tiny_box", "--patches", 200, "--method", "perceptual",
               "--out", tmp_path / "solution")
    from_cli = np.load(tmp_path / "solution" / "E.npy")
    options = procam.SolverOptions()
    options.method = "perceptual"
    lines = []
    run = procam.compensate_geometry(tiny_box, options, progress=lines.append)
    assert run.emittance.shape == from_cli.shape
    assert np.array_equal(run.emittance, from_cli)
    result = json.loads((tmp_path / "solution" / "result.json").read_text())
    assert run.summary.iterations == result["iterations"]
    assert len(lines) >= run.summary.iterations, "a progress line per iteration"


def test_solve_matches_the_solution_of_a_problem_made_by_hand():
    # Two facing patches, no bound active: B = K^-1 E, so with E from the reverse method the
    # radiosity is the desired one exactly (the closed form of DESIGN.md).
    problem = procam.Problem()
    problem.form_factors = np.array([[0.0, 0.2], [0.2, 0.0]])
    problem.area = np.array([1.0, 1.0])
    problem.reflectance = np.full((2, 3), 0.5)
    problem.adjacency = []
    problem.lower = np.zeros((2, 3))
    problem.upper = np.full((2, 3), 10.0)
    problem.desired = np.array([[0.5, 0.4, 0.3], [0.2, 0.3, 0.4]])
    srgb_to_xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    problem.rgb_to_xyz = srgb_to_xyz
    problem.white_xyz = srgb_to_xyz @ np.ones(3)
    assert problem.validate() == ""
    options = procam.SolverOptions()
    options.method = "reverse"
    solution, summary = procam.solve(problem, options)
    k = np.eye(2) - 0.5 * problem.form_factors
    assert np.allclose(solution.emittance, k @ problem.desired, atol=1e-12)
    assert np.allclose(solution.radiosity, problem.desired, atol=1e-12)
    options.method = "perceptual"
    solution, summary = procam.solve(problem, options)
    assert np.allclose(solution.radiosity, problem.desired, atol=1e-6)
    assert summary.final_cost < 1e-10
    # With one bound active the solve iterates, calling `progress` once per outer iteration.
    problem.upper = np.full((2, 3), 0.3)
    lines = []
    solution, summary = procam.solve(problem, options, progress=lines.append)
    assert summary.iterations >= 1 and len(lines) == summary.iterations
    assert np.all(solution.emittance <= 0.3 + 1e-12)


def test_two_threads_compensating_at_once_get_what_each_gets_alone():
    scenes = [procam.geometry("synthetic:tiny_box", patches=120), procam.geometry("synthetic:l_shaped", patches=150)]
    alone = [procam.compensate_geometry(g).emittance.copy() for g in scenes]
    together = [None, None]

    def work(k):
        together[k] = procam.compensate_geometry(scenes[k]).emittance.copy()

    threads = [threading.Thread(target=work, args=(k,)) for k in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=300)
    for k in range(2):
        assert np.array_equal(together[k], alone[k])


def test_bad_input_raises_one_line_naming_it(tmp_path):
    with pytest.raises(procam.IoError, match="missing.json"):
        procam.load_scene(str(tmp_path / "missing.json"))
    bad = tmp_path / "bad.json"
    bad.write_text('{"surfaces": [{"name": "a", "corners": [[0,0,0],[1,0,0],[1,1,0]], "reflectance": [2,0,0]}]}')
    with pytest.raises(procam.IoError, match="bad.json") as error:
        procam.load_scene(str(bad))
    assert "\n" not in str(error.value)
    options = procam.SolverOptions()
    with pytest.raises(ValueError, match="method"):
        options.method = "fastest"
    with pytest.raises(ValueError, match="device_preconditioner"):
        options.device_preconditioner = "jacobi"
    options.metric_rounds = 0
    with pytest.raises(ValueError):
        options.check()
    with pytest.raises(ValueError, match="photos"):
        procam.decode_structured_light(np.zeros((4, 4)), procam.StructuredLightOptions(16, 16))
    with pytest.raises(procam.IoError, match="nothing.png"):
        procam.read_image(tmp_path / "nothing.png")
    (tmp_path / "rig").mkdir()
    (tmp_path / "rig" / "rig.json").write_text('{"format": "procam rig", "version": 1, "projectors": 3}')
    with pytest.raises(procam.IoError, match="rig.json"):
        procam.read_rig(tmp_path / "rig")


def test_decoding_an_ideal_capture_gives_every_projector_pixel():
    # A camera that sees the projector's image pixel for pixel: the decoded column and row of each
    # camera pixel are its own coordinates.
    options = procam.StructuredLightOptions(64, 48)
    patterns = procam.structured_light_patterns(options)
    photos = np.stack([p[:, :, 0].astype(np.float32) for p in patterns])
    decoded = procam.decode_structured_light(photos, options)
    rows, columns = np.mgrid[0:48, 0:64]
    assert np.all(decoded.mask == 255)
    assert np.max(np.abs(decoded.column - columns)) < 0.05
    assert np.max(np.abs(decoded.row - rows)) < 0.05
    # The same photos as a list of uint8 images decode the same.
    as_list = procam.decode_structured_light([p[:, :, 0] for p in patterns], options)
    assert np.allclose(as_list.column, decoded.column, atol=1e-4)


def test_decoding_equals_the_command_line(tmp_path):
    run_procam("patterns", "--width", 64, "--height", 48, "--out", tmp_path / "patterns")
    run_procam("import", tmp_path / "patterns" / "layout.json", tmp_path / "patterns", "--out", tmp_path / "session")
    result = json.loads((tmp_path / "session" / "decode" / "result.json").read_text())
    layout = procam.read_capture_layout(tmp_path / "patterns" / "layout.json")
    files = sorted((tmp_path / "patterns").glob("pat*.png"))
    decoded = procam.decode_structured_light([procam.read_image(f) for f in files], layout)
    assert int(np.count_nonzero(decoded.mask)) == result["decoded"]


def test_camera_calibration_on_opencvs_own_photos_meets_opencvs_reference():
    # OpenCV's left camera set (opencv-doc): its published reference fx 532.81, and procam's
    # command line on the same photos (docs/calibration.md) within 0.2%.
    folder = SHARED / "data" / "real" / "opencv_left"
    board = procam.Chessboard(9, 6, 1.0)
    views, size = [], None
    for path in sorted(folder.glob("*.jpg")):
        image = procam.read_image(path)
        size = (image.shape[1], image.shape[0])
        corners = procam.detect_chessboard(image, board)
        if corners is not None:
            views.append(corners)
    assert len(views) >= 10
    calibration, summary = procam.calibrate_camera(views, board, *size, lens_model="LENSMODEL_OPENCV5",
                                                   reject_outliers=False)
    assert summary.converged, summary.message
    fx = calibration.intrinsics[0]
    assert abs(fx - 532.81) / 532.81 < 0.002


def python_blocks():
    source = pathlib.Path(os.environ.get("PROCAM_SOURCE_DIR", ".")) / "docs" / "python.md"
    text = source.read_text()
    return [block.split("```", 1)[0] for block in text.split("```python\n")[1:]]


def test_the_documented_loop_runs_and_draws(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    exec(compile(python_blocks()[0], "docs/python.md", "exec"), {})
    assert (tmp_path / "desired_vs_predicted.png").stat().st_size > 1000


def test_the_documented_pytorch_loop_runs(tmp_path, monkeypatch):
    pytest.importorskip("torch")
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(python_blocks()[1], "docs/python.md", "exec"), scope)
    # The network learned: what the room shows came closer to the target.
    assert scope["losses"][-1] < 0.8 * scope["losses"][0]


def test_a_room_with_projectors_compensates_and_writes_as_the_command_line_does(tmp_path):
    # A scene file with its projectors and camera (procam scene write): the projectors' light
    # bounds the emittance, on the command line and here alike.
    run_procam("scene", "write", "tiny_box", "--out", tmp_path / "rig")
    scene = tmp_path / "rig" / "tiny_box.json"
    run_procam("compensate", scene, "--patches", 150, "--out", tmp_path / "cli")
    room = procam.load_room(str(scene), patches=150)
    assert room.projectors and room.upper.shape == (room.size, 3)
    run = procam.compensate(room)
    assert np.all(run.emittance <= room.upper + 1e-12) and np.all(run.emittance >= room.lower - 1e-12)
    procam.write_solution(room, run, tmp_path / "python")
    assert np.array_equal(np.load(tmp_path / "python" / "E.npy"), np.load(tmp_path / "cli" / "E.npy"))
    back = procam.read_solution(tmp_path / "python")
    assert back.patches == room.size and np.array_equal(back.emittance, run.emittance)
    # The projector images equal what `procam project` writes for the same solution.
    run_procam("project", tmp_path / "cli", "--out", tmp_path / "images")
    images = procam.projector_images(room, run.emittance)
    assert len(images) == len(room.projectors)
    for name, image in zip(room.projectors, images):
        written = procam.read_image(tmp_path / "images" / f"{name}.png")
        assert written.shape == image.shape
        assert np.array_equal(written.astype(np.uint16), image)
    # The solution checks the room it is loaded with: another patch count is refused by name.
    with pytest.raises(procam.IoError, match="patches"):
        procam.load_room(str(scene), patches=400, solution=tmp_path / "python")


def look_at(eye, target):
    """(R, t) of a camera at `eye` looking at `target`, y down: x_cam = R x_world + t."""
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross([0.0, -1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])
    return r, -r @ eye


def test_board_projector_calibration_recovers_a_known_pinhole_pair():
    # A pinhole camera and a pinhole projector 0.2 m to its right, a 9x6 board of 3 cm squares seen
    # in seven tilted poses; exact corners in both. The calibration recovers both lenses and the
    # projector's pose (independent truth: the numbers the corners were made with).
    board = procam.Chessboard(9, 6, 0.03)
    corners = np.array([[0.03 * (k % 9), 0.03 * (k // 9), 0.0] for k in range(54)])
    camera_k = np.array([[1000.0, 0, 640], [0, 1000.0, 400], [0, 0, 1]])
    projector_k = np.array([[1400.0, 0, 512], [0, 1400.0, 700], [0, 0, 1]])
    r_pc, _ = look_at(np.zeros(3), np.array([-0.15, 0.0, 1.0]))
    t_pc = np.array([-0.2, 0.0, 0.0])

    def project(k, points):
        q = points @ k.T
        return q[:, :2] / q[:, 2:]

    poses = []
    for tilt_x, tilt_y, distance in [(0, 0, 0.9), (25, 0, 1.0), (-25, 0, 0.8), (0, 25, 1.1),
                                     (0, -25, 0.9), (18, 18, 1.0), (-18, 15, 0.95)]:
        ax, ay = np.radians(tilt_x), np.radians(tilt_y)
        rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
        ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
        in_camera = (corners - corners.mean(axis=0)) @ (ry @ rx).T + np.array([0.0, 0.0, distance])
        in_projector = in_camera @ r_pc.T + t_pc
        poses.append((project(camera_k, in_camera), project(projector_k, in_projector), [True] * 54))
    calibration, summary = procam.calibrate_board_projector(poses, board, (1280, 800), (1024, 768))
    assert summary.converged, summary.message
    assert summary.camera_rms < 1e-3 and summary.projector_rms < 1e-3
    assert np.allclose(calibration.camera_intrinsics[:4], [1000, 1000, 640, 400], atol=0.5)
    assert np.allclose(calibration.projector_intrinsics[:4], [1400, 1400, 512, 700], atol=0.5)
    pose = calibration.projector_from_camera
    assert np.allclose(pose[:3, 3], t_pc, atol=1e-3)
    # mrcal's light regularisation of the centres (on by default) leaves the rotation within
    # 5e-4 of the truth (0.03°); without noise nothing else moves it.
    assert np.allclose(pose[:3, :3], r_pc, atol=5e-4)
