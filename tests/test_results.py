"""Results folders (experiments/results/<question>/): each says how it was made."""
import os
import re
import shlex

import pytest

from conftest import REPO
from renerf_jax.configs import load_config

RESULTS = REPO / 'experiments' / 'results'
FOLDERS = sorted(p for p in RESULTS.iterdir() if p.is_dir() and (p / 'README.md').exists())
# At a line's start (an indented block) or in inline code, after optional VAR=value.
COMMAND = re.compile(r'(?:^[ \t]*|`)(?:[A-Z_]+=\S*\s+)*python\s+(\S+\.py)([^\n`]*)', re.M)


def commands(readme):
  """(script, argument list) of each `python <script>.py ...` line of a README, with
  backslash continuations joined."""
  text = readme.read_text().replace('\\\n', ' ')
  out = []
  for m in COMMAND.finditer(text):
    out.append((m.group(1), shlex.split(m.group(2).replace('...', ''))))
  return out


def config_args(args):
  """The gin files a command names (--config A B ..., --gin_configs=A)."""
  files, i = [], 0
  while i < len(args):
    a = args[i]
    if a.startswith('--gin_configs='):
      files.append(a.split('=', 1)[1])
    elif a == '--config':
      i += 1
      while i < len(args) and not args[i].startswith('--'):
        files.append(args[i])
        i += 1
      continue
    i += 1
  return files


def test_results_folders_exist():
  assert len(FOLDERS) >= 4, FOLDERS


@pytest.mark.parametrize('folder', FOLDERS, ids=[f.name for f in FOLDERS])
def test_each_results_folder_names_commands_that_exist_and_configs_that_parse(folder):
  cmds = commands(folder / 'README.md')
  assert cmds, f'{folder.name}/README.md names no `python <script>.py` command'
  for script, args in cmds:
    assert (REPO / script).is_file(), f'{folder.name}: {script} does not exist'
    for gin in config_args(args):
      path = gin if os.path.isabs(gin) else str(REPO / gin)
      if not os.path.exists(path):
        path = str(REPO / 'gin_configs' / gin)
      load_config([path])  # raises on a config that does not parse


def test_command_parsing_handles_continuations_and_config_lists(tmp_path):
  readme = tmp_path / 'README.md'
  readme.write_text('Run:\n\n    python experiments/renerf_scenes.py --name x \\\n'
                    '      --config a.gin b.gin --seeds 0 1\n'
                    'and `python train.py --gin_configs=c.gin --run_dir=...` once.\n')
  (c1, a1), (c2, a2) = commands(readme)
  assert c1 == 'experiments/renerf_scenes.py' and config_args(a1) == ['a.gin', 'b.gin']
  assert c2 == 'train.py' and config_args(a2) == ['c.gin']
