"""Restoration on rendered pairs: DeP (denoise, ÷γ, Wiener deconvolution, demosaic), the UNet and the
ResNet of the paper, training, evaluation under a stated metric protocol, LPIPS and MTCNN.

    data.py      pairs of a dataset folder as a torch Dataset (Bayer-preserving crops)
    models.py    UNet (and unet-wide-fine), ResNet, the model registry and TOML configs; counting.py: parameters
                 and MACs
    models_conditioned.py  wiener-unet, given the panel's description (conditioning.py: the description's tensors)
    dep.py       DeP; known.py: the kernels and γ DeP may know
    train.py     training with atomic checkpoints and bit-identical resume; losses.py; checkpoints.py: a run's files
    evaluate.py  PSNR/SSIM/LPIPS, parameters, MACs, ms/MP, the paper's table layout
    lpips.py     LPIPS (AlexNet) in torch; mtcnn.py: MTCNN face detection
    studies/     the face-detection study, the results loop (RESULTS.md), the capacity study and others
"""
