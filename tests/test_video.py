"""Rendered colonoscopy frames and fused partials on a straight tube, whose depth and surface are known exactly."""

import json

import numpy as np
import pytest
from PIL import Image
from shapes import straight

from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.colon import tube_colon
from colonbench.video.fusion import apply_drift, degrade_depth, tsdf_fuse
from colonbench.video.withdrawal import FrameCaster, Intrinsics, tum_to_poses

RADIUS = 20.0


@pytest.fixture(scope="module")
def tube():
    """A straight open tube of radius 20 mm along z, 0-200 mm, 0.5 mm rings of 256 vertices."""
    colon = tube_colon(straight(200.0), RADIUS, ring_spacing_mm=0.5, n_around=256)
    return colon, SurfaceScene(colon.mesh.vertices, colon.mesh.faces)


def looking(position, direction, up=(0.0, 0.0, 1.0)):
    """Camera-to-world pose at ``position`` looking along ``direction``, image rows running against ``up``."""
    z = np.asarray(direction, float) / np.linalg.norm(direction)
    y = -(np.asarray(up, float) - (np.dot(up, z)) * z)
    y /= np.linalg.norm(y)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([np.cross(y, z), y, z], axis=1)
    pose[:3, 3] = position
    return pose


def wall_distance(points):
    """Distance of points from the tube's wall, mm."""
    return np.abs(np.hypot(points[:, 0], points[:, 1]) - RADIUS)


def test_depth_of_straight_tube_matches_the_analytic_depth(tube):
    _, scene = tube
    intr = Intrinsics.wide(128, fov_deg=140.0)
    ox = 6.0  # off the axis, looking across it at the wall
    pose = looking([ox, 0.0, 100.0], [1.0, 0.0, 0.0])
    depth, face = FrameCaster(scene, intr).depth(pose)
    rays = intr.rays() @ pose[:3, :3].T  # world directions with a unit z in the camera frame
    a = np.sum(rays[:, :2] ** 2, axis=1)
    b = 2 * ox * rays[:, 0]
    c = ox ** 2 - RADIUS ** 2
    exact = ((-b + np.sqrt(b ** 2 - 4 * a * c)) / (2 * a)).reshape(depth.shape)
    z_hit = 100.0 + exact * rays[:, 2].reshape(depth.shape)
    inside = (z_hit > 5) & (z_hit < 195)
    centre = (intr.height // 2, intr.width // 2)
    assert abs(depth[centre] - exact[centre]) < 0.1
    assert abs(exact[centre] - (RADIUS - ox)) < 0.1  # the centre pixel looks straight at the wall
    err = np.abs(depth - exact)[inside]
    assert inside.mean() > 0.9 and np.percentile(err, 99) < 0.1
    assert (face[inside] >= 0).all()


def ring_of_frames(z_values, turns=24):
    """Cameras on the tube's axis looking at the wall all around, at each z."""
    poses = []
    for z in z_values:
        for a in np.linspace(0, 2 * np.pi, turns, endpoint=False):
            poses.append(looking([0.0, 0.0, z], [np.cos(a), np.sin(a), -0.3]))
    return np.array(poses)


def test_fusing_perfect_frames_gives_the_true_surface(tube):
    _, scene = tube
    intr = Intrinsics.wide(128, fov_deg=120.0)
    caster = FrameCaster(scene, intr)
    poses = ring_of_frames([90.0, 100.0, 110.0])
    v, f = tsdf_fuse([caster.depth(p)[0] for p in poses], poses, intr, voxel_mm=0.5, trunc_mm=2.0,
                     max_depth_mm=60.0)
    mid = (v[:, 2] > 85) & (v[:, 2] < 105)
    assert len(f) > 1000 and mid.sum() > 1000
    d = wall_distance(v[mid])
    assert np.median(d) < 0.1 and np.percentile(d, 99) < 0.5


def test_drift_moves_the_fused_surface_by_the_expected_amount(tube):
    _, scene = tube
    intr = Intrinsics.wide(96, fov_deg=100.0)
    caster = FrameCaster(scene, intr)
    poses = np.array([looking([0.0, 0.0, z], [1.0, 0.0, 0.0]) for z in np.arange(90.0, 111.0, 2.0)])
    depths = [caster.depth(p)[0] for p in poses]
    k = len(poses)
    zero = {"rotvec": np.zeros((k, 3)), "trans": np.zeros((k, 3)), "log_scale": np.zeros(k)}
    np.testing.assert_allclose(apply_drift(poses, zero, anchor=5), poses, atol=1e-9)

    # a 2 mm error in the step to frame 1, along that camera's z (its view: world +x), moves frames 1.. by it
    known = {**zero, "trans": np.zeros((k, 3))}
    known["trans"][1] = [0.0, 0.0, 2.0]
    drifted = apply_drift(poses, known, anchor=0)
    np.testing.assert_allclose(drifted[1:, :3, 3] - poses[1:, :3, 3], np.tile([2.0, 0.0, 0.0], (k - 1, 1)),
                               atol=1e-9)
    v, _ = tsdf_fuse(depths[1:], drifted[1:], intr, voxel_mm=0.5, trunc_mm=2.0, max_depth_mm=60.0)
    front = (np.abs(v[:, 1]) < 4) & (v[:, 0] > 0) & (v[:, 2] > 95) & (v[:, 2] < 105)
    assert front.sum() > 50
    assert abs(np.median(v[front, 0]) - (RADIUS + 2.0)) < 0.2

    # a scale drift of 10 %: the wall seen from the axis lies 10 % farther
    scaled = [degrade_depth(np.random.default_rng(0), d, 0.0, 0.0, np.log(1.1)) for d in depths]
    v, _ = tsdf_fuse(scaled, poses, intr, voxel_mm=0.5, trunc_mm=2.0, max_depth_mm=60.0)
    front = (np.abs(v[:, 1]) < 4) & (v[:, 0] > 0) & (v[:, 2] > 95) & (v[:, 2] < 105)
    assert abs(np.median(v[front, 0]) - 1.1 * RADIUS) < 0.2


def test_colour_frames_line_up_with_the_depth_frames(tube):
    from colonbench.video.mucosa import ColourRenderer

    colon, scene = tube
    v, f = colon.mesh.vertices, colon.mesh.faces
    red = v[:, 1] > 0  # the half of the tube at world y > 0, which the image shows on its right
    colours = np.where(red[:, None], [[0.9, 0.1, 0.1]], [[0.1, 0.9, 0.1]])
    intr = Intrinsics.wide(96, fov_deg=100.0)
    pose = looking([0.0, 0.0, 100.0], [1.0, 0.0, 0.0])
    with ColourRenderer(intr, light_intensity=3000.0) as renderer:
        renderer.set_mesh(v, f, colours)
        rgb = renderer.render(pose).astype(int)
    _, face = FrameCaster(scene, intr).depth(pose)
    cent = scene.centroids[np.maximum(face, 0)]
    hit = face >= 0
    sure = hit & (np.abs(cent[..., 1]) > 1.0)  # away from the colour edge
    expect_red = cent[..., 1] > 0
    seen_red = rgb[..., 0] > rgb[..., 1]
    assert sure.mean() > 0.8
    assert (seen_red[sure] == expect_red[sure]).mean() > 0.99
    assert expect_red[sure].any() and (~expect_red[sure]).any()


def test_frame_dataset_reprojects_surface_points_onto_their_pixels(tube, tmp_path):
    from colonbench.datagen.config import VideoConfig
    from colonbench.video.framedata import png_to_depth, write_video

    colon, scene = tube
    config = VideoConfig(speed_mm_s=(10.0, 10.0), push_back_per_100mm=0.0)
    meta = write_video(colon, tmp_path / "v", seed=3, start_mm=60.0, end_mm=140.0, config=config, size=96, fps=4.0,
                       face_ids=True, max_frames=5, gif_seconds=1.0, gif_size=48, progress=False)
    assert meta["frames"] == 5
    out = tmp_path / "v"
    intr = json.loads((out / "intrinsics.json").read_text())
    K = np.array(intr["K"])
    times, poses = tum_to_poses((out / "poses.txt").read_text().splitlines())
    assert len(poses) == 5 and np.allclose(np.diff(times), 0.25)
    vis = np.load(out / "visibility.npz")
    for i in (0, 4):
        depth = png_to_depth(np.asarray(Image.open(out / "depth" / f"{i:06d}.png")))
        face = np.load(out / "faces" / f"{i:06d}.npz")["face"]
        assert np.asarray(Image.open(out / "rgb" / f"{i:06d}.png")).shape == (96, 96, 3)
        # every pixel's depth, back-projected through the pose, lies on the surface (to the PNG's 0.05 mm
        # rounding of z, stretched along the oblique rays of the image's corners)
        vv, uu = np.nonzero(depth > 0)
        cam = np.stack([(uu - K[0, 2]) / K[0, 0], (vv - K[1, 2]) / K[1, 1], np.ones(len(uu))], 1) * depth[vv, uu, None]
        world = cam @ poses[i][:3, :3].T + poses[i][:3, 3]
        assert np.percentile(wall_distance(world), 99) < 0.15 and np.median(wall_distance(world)) < 0.05
        # a seen face's centroid projects onto a pixel showing that face (or its neighbour within a pixel's width)
        seen = vis["faces"][vis["offsets"][i]:vis["offsets"][i + 1]]
        assert len(seen) > 100
        c = scene.centroids[seen]
        local = (c - poses[i][:3, 3]) @ poses[i][:3, :3]
        uv = np.round(local[:, :2] / local[:, 2:] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]).astype(int)
        ok = (uv >= 0).all(axis=1) & (uv[:, 0] < 96) & (uv[:, 1] < 96)
        shown = scene.centroids[face[uv[ok, 1], uv[ok, 0]]]
        step = np.linalg.norm(local[ok], axis=1) / K[0, 0]  # one pixel's footprint at that distance, mm
        assert np.mean(np.linalg.norm(shown - c[ok], axis=1) <= 2 * step + 0.5) > 0.95
    assert (out / "preview.gif").is_file() and (out / "colon.ply").is_file()


def test_video_partial_observes_exactly_and_lies_on_the_wall(tube):
    from colonbench.datagen.config import VideoConfig
    from colonbench.datagen.sample import make_sample
    from colonbench.datagen.segments import segment_surface

    colon, scene = tube
    surface = segment_surface(scene, colon.centerline, 70.0, 130.0)
    perfect = VideoConfig(depth_noise=(0.0, 0.0), edge_blur_px=(0.0, 0.0), drift_rot_deg=(0.0, 0.0),
                          drift_trans_mm=(0.0, 0.0), drift_scale=(0.0, 0.0), tracking_loss_per_100mm=0.0,
                          voxel_mm=0.75)
    s = make_sample(np.random.default_rng(1), scene, colon.centerline, surface, "video", video=perfect)
    areas = surface.mesh.area_faces
    assert s.coverage == pytest.approx(areas[s.observed_faces].sum() / areas.sum())
    assert 0.3 < s.coverage <= 1.0
    assert len(s.partial_points) > 0.8 * 2.0 * areas[s.observed_faces].sum()
    assert np.percentile(wall_distance(s.partial_points), 95) < 0.5
    assert ((s.partial_points[:, 2] >= 70.0 - 1e-6) & (s.partial_points[:, 2] <= 130.0 + 1e-6)).all()
    info = s.info["video"]
    assert info["depth_noise"] == 0.0 and info["frames_fused"] > 10 and 30.0 <= info["reach_mm"] <= 80.0

    noisy = make_sample(np.random.default_rng(1), scene, colon.centerline, surface, "video",
                        video=VideoConfig(depth_noise=(0.02, 0.02), drift_trans_mm=(0.5, 0.5),
                                          tracking_loss_per_100mm=0.0))
    assert np.percentile(wall_distance(noisy.partial_points), 95) > np.percentile(wall_distance(s.partial_points), 95)


def test_a_manifest_mixes_video_with_camera_and_records_the_settings(tmp_path):
    import yaml

    from colonbench.shards.dataset import generate
    from colonbench.shards.reader import Shard, dataset_files

    from conftest import MANIFESTS

    manifest = yaml.safe_load((MANIFESTS / "smoke.yaml").read_text())
    manifest["name"] = "video-mix"
    manifest["config"]["video"] = {"image_px": 64, "fps": 5.0}
    manifest["splits"] = {"test": {"colons": {"first": 0, "count": 1}, "segments_per_length": 1, "permutations": 3,
                                   "hole_models": {"camera": 0.5, "video": 0.5}}}
    path = tmp_path / "video-mix.yaml"
    path.write_text(yaml.safe_dump(manifest))
    generate(path, tmp_path / "data", workers=1, progress=False)
    (shard,) = dataset_files(tmp_path / "data", "test")
    with Shard(shard) as sh:
        models = [sh.sample(i)["hole_model"] for i in range(len(sh))]
        info = json.loads(sh.h5.attrs["sample_info"])
    assert sorted(set(models)) == ["camera", "video"]
    assert [i is not None for i in info] == [m == "video" for m in models]
    assert all(i["frames_fused"] > 0 and "drift_trans_mm" in i for i in info if i is not None)


def test_video_command_writes_a_dataset_and_refuses_bad_input(tmp_path, capsys):
    from colonbench.cli import main

    from conftest import MANIFESTS

    out = tmp_path / "v"
    assert main(["video", str(MANIFESTS / "smoke.yaml"), "--colon", "2", "--out", str(out), "--start-mm", "200",
                 "--end-mm", "260", "--size", "48", "--fps", "2", "--max-frames", "3", "--gif-seconds", "0",
                 "--quiet"]) == 0
    assert len(list((out / "rgb").glob("*.png"))) == 3 and len(list((out / "depth").glob("*.png"))) == 3
    assert not (out / "preview.gif").exists()
    meta = json.loads((out / "video.json").read_text())
    assert meta["frames"] == 3 and meta["source"] == {"manifest": str(MANIFESTS / "smoke.yaml"), "colon": "2"}
    capsys.readouterr()
    for argv, message in ((["--colon", "2"], "--colon picks a colon of a manifest"),
                          ([str(MANIFESTS / "smoke.yaml"), "--colon", "gca00060"], "neither a procedural colon id"),
                          ([str(MANIFESTS / "smoke.yaml"), "--start-mm", "5000"], "is not inside the colon")):
        assert main(["video", *argv, "--out", str(tmp_path / "bad"), "--quiet"]) == 2
        assert message in capsys.readouterr().err


def test_fused_meshes_come_out_in_one_order_whatever_order_open3d_gives():
    from colonbench.video.fusion import canonical_mesh

    rng = np.random.default_rng(0)
    colon = tube_colon(straight(20.0), RADIUS, ring_spacing_mm=1.0, n_around=32)
    v, f = colon.mesh.vertices, colon.mesh.faces
    perm = rng.permutation(len(v))
    inverse = np.argsort(perm)
    shuffled_f = inverse[f][rng.permutation(len(f))]
    shuffled_f = np.roll(shuffled_f, 1, axis=1)  # each triangle starting at another corner, same orientation
    a_v, a_f = canonical_mesh(v, f)
    b_v, b_f = canonical_mesh(v[perm], shuffled_f)
    np.testing.assert_array_equal(a_v, b_v)
    np.testing.assert_array_equal(a_f, b_f)
    assert np.allclose(np.sort(face_normals(a_v, a_f), axis=0), np.sort(face_normals(v, f), axis=0))  # orientation


def face_normals(vertices, faces):
    """Unnormalised normals of triangles (their orientation's sign kept)."""
    return np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
