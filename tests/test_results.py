"""Results folders (experiments/results/<question>/): each says how it was made."""
import json
import os
import pathlib
import re
import shlex

import pytest

from conftest import REPO
from renerf_jax.configs import load_config

RESULTS = REPO / 'experiments' / 'results'
FOLDERS = sorted(p for p in RESULTS.iterdir() if p.is_dir() and (p / 'README.md').exists())
# At a line's start (an indented block) or in inline code, after optional VAR=value:
# `python -m package.module ...` or `python path/script.py ...`.
COMMAND = re.compile(r'(?:^[ \t]*|`)(?:[A-Z_]+=\S*\s+)*python\s+(?:-m\s+([\w.]+)|(\S+\.py))'
                     r'([^\n`]*)', re.M)


def commands(readme):
  """(how, target, argument list) of each `python -m <module> ...` (how '-m') or
  `python <script>.py ...` (how 'file') line of a README, with backslash continuations
  joined."""
  text = readme.read_text().replace('\\\n', ' ')
  out = []
  for m in COMMAND.finditer(text):
    how, target = ('-m', m.group(1)) if m.group(1) else ('file', m.group(2))
    out.append((how, target, shlex.split(m.group(3).replace('...', ''))))
  return out


def command_problem(how, target, repo=REPO):
  """Why `python -m <target>` / `python <target>` run from the repository root would not
  find what it runs (None if it would). A module must be a file of a package (every folder
  on its way has an __init__.py); a script in such a package (experiments/, benchmarks/) is run
  with -m, as its imports of the package need."""
  if how == '-m':
    *packages, name = target.split('.')
    for i in range(len(packages)):
      if not repo.joinpath(*packages[:i + 1], '__init__.py').is_file():
        return f'python -m {target}: {".".join(packages[:i + 1])} is not a package'
    if not (repo.joinpath(*packages, name + '.py').is_file()
            or repo.joinpath(*packages, name, '__main__.py').is_file()):
      return f'python -m {target}: no module {target} in the repository'
    return None
  if not (repo / target).is_file():
    return f'{target} does not exist'
  path = pathlib.PurePosixPath(target)
  if (repo / path.parent / '__init__.py').is_file():
    return (f'{target} is a module of a package: run it as '
            f'python -m {".".join(path.with_suffix("").parts)}')
  return None


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


def check_command(where, how, target, args):
  """Asserts that a command named in `where` finds what it runs and that every gin file
  it names parses (load_config raises on one that does not)."""
  problem = command_problem(how, target)
  assert problem is None, f'{where}: {problem}'
  for gin in config_args(args):
    path = gin if os.path.isabs(gin) else str(REPO / gin)
    if not os.path.exists(path):
      path = str(REPO / 'gin_configs' / gin)
    load_config([path])


def test_results_folders_exist():
  assert len(FOLDERS) >= 4, FOLDERS


@pytest.mark.parametrize('folder', FOLDERS, ids=[f.name for f in FOLDERS])
def test_each_results_folder_names_commands_that_exist_and_configs_that_parse(folder):
  cmds = commands(folder / 'README.md')
  assert cmds, (f'{folder.name}/README.md names no `python -m <module>` or '
                '`python <script>.py` command')
  for how, target, args in cmds:
    check_command(folder.name, how, target, args)


def test_command_parsing_handles_continuations_and_config_lists(tmp_path):
  readme = tmp_path / 'README.md'
  readme.write_text('Run:\n\n    python -m experiments.renerf_scenes --name x \\\n'
                    '      --config a.gin b.gin --seeds 0 1\n'
                    'and `python train.py --gin_configs=c.gin --run_dir=...` once.\n'
                    '    OUT=/tmp/o python experiments/renerf_scenes.py --config d.gin\n')
  (h1, c1, a1), (h2, c2, a2), (h3, c3, a3) = commands(readme)
  assert (h1, c1) == ('-m', 'experiments.renerf_scenes')
  assert config_args(a1) == ['a.gin', 'b.gin'] and a1[:2] == ['--name', 'x']
  assert (h2, c2) == ('file', 'train.py') and config_args(a2) == ['c.gin']
  assert (h3, c3) == ('file', 'experiments/renerf_scenes.py') and config_args(a3) == ['d.gin']


def test_a_command_must_run_a_module_or_script_that_exists():
  for how, target in (('-m', 'experiments.renerf_scenes'), ('-m', 'benchmarks.bench_hessian'),
                      ('file', 'train.py'),
                      ('file', 'experiments/results/xla_cpu_crash/repro.py')):
    assert command_problem(how, target) is None, target
  assert 'no module experiments.no_such_table' in command_problem(
      '-m', 'experiments.no_such_table')
  assert 'gin_configs is not a package' in command_problem('-m', 'gin_configs.demo')
  assert 'does not exist' in command_problem('file', 'experiments/no_such_table.py')
  # The scripts of the experiments package import it: they run with -m only.
  assert 'run it as python -m experiments.renerf_scenes' in command_problem(
      'file', 'experiments/renerf_scenes.py')


def test_readme_commands_exist_and_their_configs_parse():
  """The README's commands (set-up, reproduce each table, using it) name modules and
  scripts that exist and configs that parse; its result links name folders that exist."""
  readme = REPO / 'README.md'
  cmds = commands(readme)
  assert sum(how == '-m' for how, _, _ in cmds) >= 4, cmds
  for how, target, args in cmds:
    if how == '-m' and target == 'pytest':
      continue
    check_command('README.md', how, target, args)
  links = re.findall(r'\]\((experiments/results/[\w/]+)\)', readme.read_text())
  assert links and all((REPO / link).is_dir() for link in links), links
  assert len(readme.read_text().splitlines()) <= 120  # issue 35: read in two minutes


def test_the_forest_plot_draws_the_tables_numbers(tmp_path):
  """Issue 62: the README's picture (experiments/results/forest_plot.png, `python -m
  experiments.forest_plot`) holds the tables' numbers: the committed forest_plot.json is
  what the tables give now, and each line, printed as its table prints a cell, stands in
  the R1 row of that table's pooled part."""
  from experiments import forest_plot, paired  # pylint: disable=g-import-not-at-top
  lines = forest_plot.lines(str(RESULTS))
  committed = json.loads((RESULTS / 'forest_plot.json').read_text())
  assert committed['lines'] == lines, 'stale: run python -m experiments.forest_plot'
  assert committed['command'] == 'python -m experiments.forest_plot'
  assert {line['group'] for line in lines} == {g for g, _, _, _ in forest_plot.SOURCES}
  assert len(lines) >= 20
  for line in lines:
    md = (RESULTS / line['table']).with_suffix('.md').read_text()
    pooled = md[md.index('### Over scenes'):]
    [r1_row] = [ln for ln in pooled.splitlines() if ln.startswith('| R1 |')]
    assert f"| {paired.format_cell(line)} |" in r1_row, (line['table'], line['comparison'])
    lo, hi = line['ci']
    assert lo <= line['mean'] <= hi and line['n'] >= 2
    assert line['shown'] == (line['p_holm'] < 0.05 and lo > 0.)
  # Drawn from the same numbers, into another folder.
  forest_plot.main(['--out', str(tmp_path / 'fp')])
  assert json.loads((tmp_path / 'fp.json').read_text())['lines'] == lines
  assert (tmp_path / 'fp.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
  readme = (REPO / 'README.md').read_text()
  assert '](experiments/results/forest_plot.png)' in readme
