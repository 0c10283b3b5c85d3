"""The 3D Gaussian Splatting backbone (Config.backbone = 'gaussians') as the round driver
sees it (backbones.Backbone): whole images a step, pseudo-views and the cheap evaluation
from whole renders, the round's Gaussians exported as a .ply."""
from renerf_jax import rundir
from renerf_jax.backbones import Backbone, cheap_eval_by_rendering, synthesize_by_rendering
from renerf_jax.evaluation import evaluate_views
from renerf_jax.gaussians import ply
from renerf_jax.gaussians import training as gs_training


def gaussians_init_params(config):
  """The Gaussians' parameter template: Config.gs_capacity empty slots."""
  return gs_training.init_params(config)


def gaussians_train(config, scene, out_dir, pseudo, **kwargs):
  """3DGS from scratch on the real views plus `pseudo` (whole images, drawn uniformly
  while the pseudo-views are on)."""
  return gs_training.train_gaussians(config, scene, out_dir, pseudo, **kwargs)


def gaussians_render_views(config, scene, params, poses, show_progress=False):
  """RGB, expected depth and accumulated opacity of the Gaussians at `poses`."""
  return gs_training.render_views(config, scene, params, poses, show_progress=show_progress)


def gaussians_synthesize(config, scene, params, show_progress=False):
  return synthesize_by_rendering(gaussians_render_views, config, scene, params,
                                 show_progress)


def gaussians_cheap_eval_fn(config, scene):
  return cheap_eval_by_rendering(gaussians_render_views, config, scene)


def gaussians_evaluate(config, scene, params, show_progress=False):
  """Test-view metrics and renders of the Gaussians (evaluation.Evaluation); the views
  are rendered in one call (split across processes when there are several)."""
  out = gaussians_render_views(config, scene, params, scene.poses[scene.test_idx],
                               show_progress=show_progress)

  def render_view(j, i):
    del i
    return {'rgb': out['rgb'][j], 'distance': out['depth'][j]}
  return evaluate_views(config, scene, render_view)


def gaussians_export(params, rdir):
  """The round's Gaussians as rdir/point_cloud.ply, the reference 3DGS layout that
  splat viewers open (active Gaussians only)."""
  ply.write_ply(rundir.point_cloud_path(rdir), params)


BACKBONE = Backbone(name='gaussians', init_params=gaussians_init_params,
                    train=gaussians_train, synthesize=gaussians_synthesize,
                    cheap_eval_fn=gaussians_cheap_eval_fn, evaluate=gaussians_evaluate,
                    render_views=gaussians_render_views, export=gaussians_export)
