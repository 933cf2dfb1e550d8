"""Files, in one place, each reader beside its writer; every write atomic (files.atomic_path).

    files.py       atomic writes, JSON, text, CSV, NPZ, figures, TOML reading
    exr.py         OpenEXR (linear float32, named channels): the one reader and writer
    images.py      PNG previews
    dng.py         the RAW mosaic as a DNG (libraw, rawpy and RAW editors open it), with its colour matrix
    previews.py    sRGB previews of band images and camera RGB
    band_image.py  render.exr + render.json  ⇄  BandImage
    capture.py     the files of a synthesis (gt.exr, <display>/raw.dng, capture.json, …) and
                   their readers (load_packed, load_gt)
    kernels.py     the files of `udc-render psf` (psf.npz, psf.exr, psf.json, plots)
    plots.py       PSF, MTF, banding and side-by-side figures (matplotlib, Agg, chosen when plotting)
"""
