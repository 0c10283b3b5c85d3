"""Where does Re-Nerfing help, on which backbone, by how much, for sure? One picture.

A forest plot of R1's paired PSNR gain over every reference the current tables hold:
one line per (backbone, scene group, comparison), grouped by scene type (forward-facing
LLFF / around an object / a real 360-degree capture / the embedded 360-degree scene) and
backbone. Each line is read from a renerf_scenes table's JSON (its pooled summary, which
is what the table's .md prints in its "Over scenes" part): the mean delta, its paired
bootstrap 95% interval (unadjusted), the number of (scene, seed) pairs, and whether the
gain or loss is shown (the interval excludes 0 and the Holm-adjusted p < 0.05: filled
marker) or not (hollow); a comparison of one pair (no interval) is left out. The paper's
R1 delta stands beside as a star where it exists: on LLFF (RegNeRF, the same scenes) and
on real 360 captures for 3DGS (mip-NeRF 360, 30 views: another data set, for scale).

  python -m experiments.forest_plot

Writes experiments/results/forest_plot.png (the README's picture) and forest_plot.json
(the numbers drawn, with the table each came from); trains nothing.
"""
import argparse
import os

from experiments import renerf_scenes, tables
from renerf_jax import figures, report

RESULTS = 'experiments/results'
# (scene group, backbone, table JSON under RESULTS, what it is). Order = order drawn.
SOURCES = (
    ('forward-facing (LLFF, 5 scenes)', 'NeRF (grid)',
     'renerf_r1_converged_llff/scenes_conv3.json', 'B converged, 3 seeds a scene'),
    ('forward-facing (LLFF, 5 scenes)', '3DGS', 'gaussians_uncapped/table1.json',
     '126x94, 3 seeds a scene'),
    ('forward-facing (LLFF, 5 scenes)', '3DGS + dropout',
     'gaussians_dropout/renerf_on_dropout.json', '126x94, 3 seeds a scene'),
    ('around an object (lego, 8 views)', 'NeRF (grid)', 'seed_matched_fox_lego/lego.json',
     '200x200'),
    ('around an object (lego, 8 views)', '3DGS', 'gaussians_wide_baseline/lego.json',
     '200x200'),
    ('around an object (lego, 8 views)', '3DGS + dropout', 'gaussians_dropout/lego.json',
     '200x200'),
    ('real 360 capture (fox, 12 views)', 'NeRF (grid)', 'seed_matched_fox_lego/fox.json',
     '67x120'),
    ('real 360 capture (fox, 12 views)', '3DGS', 'gaussians_wide_baseline/fox.json',
     '135x240'),
    ('real 360 capture (fox, 12 views)', '3DGS + dropout', 'gaussians_dropout/fox.json',
     '135x240'),
    ('real 360, paper setting (garden, 30 views)', 'NeRF (grid)',
     'paper_table2_360/grid_garden.json', '128x128, 8 seeds'),
    ('real 360, paper setting (garden, 30 views)', '3DGS',
     'paper_table2_360/gaussians_garden.json', '128x128, SfM start, 5 seeds'),
    ('real 360, paper setting (bear, dinosaur, 30 views)', 'NeRF (grid)',
     'paper_table2_360/grid_bear_dinosaur.json', '128x128, 4 seeds a scene'),
    ('real 360, paper setting (bear, dinosaur, 30 views)', '3DGS',
     'paper_table2_360/gaussians_bear_dinosaur.json', '128x128, SfM start, 3 seeds a scene'),
    ('embedded 360 scene (12 views)', 'NeRF (grid)', 'demo_orbit/orbit.json',
     "README command 1's config, 64x64"),
)
# The comparisons drawn: pooled summary key, its name, colour.
COMPARISONS = (('pooled', 'R1 - B', 'black'), ('pooled_ctrl', 'R1 - control', 'tab:blue'),
               ('pooled_2x', 'R1 - B 2x', 'tab:orange'),
               ('pooled_ctrl2x', 'R1 - control 2x', 'tab:red'))
PAPER_3DGS_360 = round(renerf_scenes.PAPER_3DGS_360[1][0] - renerf_scenes.PAPER_3DGS_360[0][0], 2)


def paper_delta(group, backbone, table):
  """The paper's R1 - B in PSNR beside a line, or None: the table's own (its LLFF scenes,
  RegNeRF) for the NeRF backbone; mip-NeRF 360's 3DGS delta for 3DGS on a real capture."""
  if backbone == 'NeRF (grid)' and table['summary'].get('paper_R1_delta_mean'):
    return table['summary']['paper_R1_delta_mean']['psnr']
  if backbone.startswith('3DGS') and group.startswith('real 360'):
    return PAPER_3DGS_360
  return None


def lines(results=RESULTS):
  """The plot's lines, read from the tables: a list of {'group', 'backbone', 'comparison',
  'table' (path under results), 'note', 'mean', 'std', 'ci', 'n', 'wins', 'p', 'p_holm',
  'shown', 'loss_shown', 'paper'} (paired.format_cell prints one as its table does), in
  drawing order."""
  out = []
  for group, backbone, path, note in SOURCES:
    table = report.read_json(os.path.join(results, path))
    r1 = table['summary']['mean']['R1']
    for key, name, _ in COMPARISONS:
      s = r1.get(key, {}).get('psnr')
      if not s or s['ci'] is None:  # no such row, or one pair: no interval to draw
        continue
      out.append({'group': group, 'backbone': backbone, 'comparison': name, 'table': path,
                  'note': note, 'mean': s['mean'], 'std': s['std'], 'ci': s['ci'],
                  'n': s['n'], 'wins': s['wins'], 'p': s['p'],
                  'p_holm': s.get('p_holm', s['p']),
                  'shown': s['shown'], 'loss_shown': s['loss_shown'],
                  'paper': paper_delta(group, backbone, table) if name == 'R1 - B' else None})
  return out


def plot(rows, path):
  """Draws the forest plot of `rows` (lines()) into `path`."""
  colours = {name: c for _, name, c in COMPARISONS}
  ys, labels, y, heads = [], [], 0., []
  prev_group = prev_backbone = None
  for row in rows:
    if row['group'] != prev_group:
      y -= 0.6
      heads.append((y, row['group']))
      y -= 1.
    elif row['backbone'] != prev_backbone:
      y -= 0.4
    prev_group, prev_backbone = row['group'], row['backbone']
    ys.append(y)
    labels.append(f"{row['backbone']}: {row['comparison']} (n {row['n']})")
    y -= 1.
  fig, axes = figures.subplots(1, 1, figsize=(9.5, 0.27 * (len(rows) + 2 * len(heads)) + 1.2))
  ax = axes[0][0]
  for yi, row in zip(ys, rows):
    lo, hi = row['ci']
    c = colours[row['comparison']]
    ax.plot([lo, hi], [yi, yi], color=c, lw=1.6)
    filled = row['shown'] or row['loss_shown']
    ax.plot([row['mean']], [yi], 'o', color=c, markersize=6,
            markerfacecolor=c if filled else 'white', markeredgewidth=1.5)
    if row['paper'] is not None:
      ax.plot([row['paper']], [yi], '*', color='tab:green', markersize=10)
    ax.annotate(f"{row['mean']:+.2f} [{lo:+.2f}, {hi:+.2f}] Holm p {row['p_holm']:.2g}",
                (1.01, yi), xycoords=('axes fraction', 'data'), va='center', fontsize=7)
  for yh, text in heads:
    ax.annotate(text, (0., yh), xycoords=('axes fraction', 'data'), va='center',
                fontsize=9, fontweight='bold')
  ax.axvline(0., color='grey', lw=0.8)
  ax.set_yticks(ys)
  ax.set_yticklabels(labels, fontsize=7.5)
  ax.set_ylim(y + 0.2, 0.2)
  ax.set_xlabel('PSNR gain of R1 [dB]: mean over n (scene, seed) pairs, paired bootstrap '
                '95% interval')
  ax.grid(True, axis='x', alpha=0.3)
  handles = [ax.plot([], [], 'o-', color=c, label=name)[0] for _, name, c in COMPARISONS]
  handles += [ax.plot([], [], 'o', color='k', markerfacecolor='white',
                      label='hollow: not shown (Holm p >= 0.05 or 0 in the interval)')[0],
              ax.plot([], [], '*', color='tab:green', markersize=10,
                      label="paper's R1 - B (LLFF: RegNeRF, these scenes; 3DGS: "
                            'mip-NeRF 360)')[0]]
  ax.legend(handles=handles, fontsize=7, loc='lower left', bbox_to_anchor=(0., 1.0),
            ncol=2, frameon=False)
  figures.save_figure(fig, path, dpi=110)


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--results', default=RESULTS, help='the results folder the tables are in')
  p.add_argument('--out', default=os.path.join(RESULTS, 'forest_plot'),
                 help='output path without extension (.png and .json are written)')
  args = p.parse_args(argv)
  rows = lines(args.results)
  report.write_json(args.out + '.json', {
      'lines': rows, 'command': tables.command_line('experiments.forest_plot', argv)})
  plot(rows, args.out + '.png')
  for row in rows:
    mark = ' shown' if row['shown'] else ' loss shown' if row['loss_shown'] else ''
    print(f"{row['group']} | {row['backbone']} | {row['comparison']}: {row['mean']:+.2f} "
          f"[{row['ci'][0]:+.2f}, {row['ci'][1]:+.2f}], n {row['n']}, Holm p "
          f"{row['p_holm']:.2g}{mark}")


if __name__ == '__main__':
  main()
