"""Write an mp4 of a drive with Gymnasium's RecordVideo wrapper (Driving-v0, pursuit driver).

Needs the extra ``rl`` (moviepy over imageio-ffmpeg, which brings its own ffmpeg). Rendering
is offscreen (``render_mode="rgb_array"``; EGL or OSMesa without a display).

    python examples/record_video.py                        # videos/drive-episode-0.mp4, 20 s of figure8
    python examples/record_video.py --route random --seconds 60 --out /tmp/videos
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
from gymnasium.wrappers import RecordVideo

import biso_cosim.envs  # noqa: F401  (registers biso_cosim/Driving-v0)
from biso_cosim.envs.baselines import PursuitDriver


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--route", default="figure8")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds")
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--out", default="videos", help="output folder")
    args = parser.parse_args()

    env = gym.make("biso_cosim/Driving-v0", route=args.route, episode_duration_s=args.seconds,
                   render_mode="rgb_array", render_width=640, render_height=360)
    env = RecordVideo(env, video_folder=args.out, name_prefix="drive", episode_trigger=lambda episode: True)
    driver = PursuitDriver(env)
    obs, info = env.reset(seed=args.seed)
    while True:
        obs, reward, terminated, truncated, info = env.step(driver(obs))
        if terminated or truncated:
            break
    env.close()  # (writes the video)
    videos = sorted(Path(args.out).glob("drive-episode-*.mp4"))
    print(f"{info['distance_m']:.0f} m driven; video: {videos[-1] if videos else 'none written'}")
    if not videos:
        raise SystemExit("no video was written")


if __name__ == "__main__":
    main()
