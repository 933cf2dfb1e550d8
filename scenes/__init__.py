"""The built-in scene files (monitor, room, hdr), shipped as package data of udc_render.scenes."""
