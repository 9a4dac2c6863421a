"""The warm-up of `make setup` (pipeline/_warmup.py) runs the whole chain and every method, and
leaves the kernels of photometric stereo, the loading and the PTM fit compiled."""
from facette.pipeline._warmup import warm_up


def test_warm_up_runs_and_compiles_the_kernels():
    seconds = warm_up(verbose=False, size=(24, 32))
    assert seconds > 0
    from facette.fit._normals_li_jit import _refine_all
    from facette.capture._pixels_jit import _median_rows, _usable
    from facette.recon._ps_consensus_jit import consensus_block
    from facette.recon._ps_robust_jit import rank_trimmed_pixels
    from facette.recon._rti_jit import ptm_colour_block
    from facette.recon._shadows_jit import bin_mean_kernel, upsample_kernel, without_kernel
    for kernel in (_refine_all, _median_rows, _usable, rank_trimmed_pixels, ptm_colour_block, consensus_block,
                   bin_mean_kernel, upsample_kernel, without_kernel):
        assert kernel.signatures, kernel
