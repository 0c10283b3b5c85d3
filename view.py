"""Looks at a run in the browser: python view.py --run_dir runs/demo [--port 8080]

Opens a local web page (viser) that renders the chosen round's model (B, R1, ...; any
backbone) from the camera you move: a small preview while it moves, the full size once it
stops. The training, test and pseudo-view cameras are frustums with their images (click
one to look through it); layers RGB, depth, accumulated opacity, uncertainty (1 - acc)
and the error against the photo at a training or test camera; two rounds side by side
("Compare with"); "Follow training" shows a run that is still training, from its newest
checkpoint. Runs on the run directory alone (its config.gin); Ctrl-C stops it.
"""
import argparse
import sys
import time

from renerf_jax import cli, jit_cache


def parse_args(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--run_dir', default='runs/demo', help='run directory (default runs/demo)')
  p.add_argument('--host', default='127.0.0.1',
                 help='address to serve on (default 127.0.0.1: this machine only; '
                      '0.0.0.0 serves the network)')
  p.add_argument('--port', type=int, default=8080)
  p.add_argument('--preview_side', type=int, default=64,
                 help='longer side in pixels of frames while the camera moves')
  p.add_argument('--full_side', type=int, default=None,
                 help="longer side in pixels once the camera stops (default: the photos')")
  p.add_argument('--max_fps', type=float, default=0.,
                 help='cap on frames a second (0: none); lower it to take less CPU from '
                      'a training run you follow')
  p.add_argument('--poll_seconds', type=float, default=2.,
                 help='how often to look for a newer checkpoint of a run in training')
  return p.parse_args(argv)


@cli.exit_on_error
def main(argv=None):
  args = parse_args(argv)
  for name in ('preview_side', 'full_side', 'port'):
    if getattr(args, name) is not None and getattr(args, name) < 1:
      raise SystemExit(f'error: --{name}={getattr(args, name)} must be >= 1')
  jit_cache.enable_compilation_cache()
  from renerf_jax.viewer import Viewer, ViewerOptions  # pylint: disable=g-import-not-at-top
  viewer = Viewer(args.run_dir, args.host, args.port, ViewerOptions(
      preview_side=args.preview_side, full_side=args.full_side, max_fps=args.max_fps,
      poll_seconds=args.poll_seconds))
  print(f'viewing {args.run_dir} at http://{args.host}:{viewer.server.get_port()} '
        '(Ctrl-C stops)', file=sys.stderr, flush=True)
  try:
    while True:
      time.sleep(1.)
  except KeyboardInterrupt:
    viewer.stop()


if __name__ == '__main__':
  main()
