"""Restoration (DeP, UNet, ResNet) on rendered pairs: not built yet, see issue 5."""
