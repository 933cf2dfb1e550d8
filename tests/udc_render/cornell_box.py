"""The standard Cornell box as Mitsuba 3 XML, written by the tests that need a user's XML scene
(test_xml_scene, test_dataset_3d): a 2 m cube (x in [-1, 1], y in [0, 2], z in [-1, 1]) open towards +z,
red left and green right walls, a square area light under the ceiling, a white sphere on the floor, seen
from the sensor's lookat."""

ORIGIN, TARGET, UP = (0.0, 1.0, 3.9), (0.1, 0.9, 0.0), (0.0, 1.0, 0.0)

SENSOR = """  <sensor type="{type}" id="cam">{extra}
    <transform name="to_world">{transform}</transform>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/></film>
  </sensor>
"""
LOOKAT = '<lookat origin="{}" target="{}" up="{}"/>'.format(
    *(", ".join(f"{v:g}" for v in p) for p in (ORIGIN, TARGET, UP)))


def wall(name, rgb, transform):
    return (f'  <shape type="rectangle" id="{name}">\n    <transform name="to_world">{transform}</transform>\n'
            f'    <bsdf type="diffuse"><rgb name="reflectance" value="{rgb}"/></bsdf>\n  </shape>\n')


# the standard Cornell box: 2 m cube (x in [-1, 1], y in [0, 2], z in [-1, 1]) open towards +z, red left
# and green right walls, a square area light under the ceiling, a white sphere on the floor
CBOX = ('<scene version="3.0.0">\n{sensor}'
        + wall("floor", "0.725, 0.71, 0.68", '<rotate x="1" angle="-90"/>')
        + wall("ceiling", "0.725, 0.71, 0.68", '<rotate x="1" angle="90"/><translate y="2"/>')
        + wall("back", "0.725, 0.71, 0.68", '<translate y="1" z="-1"/>')
        + wall("left", "0.63, 0.065, 0.05", '<rotate y="1" angle="90"/><translate x="-1" y="1"/>')
        + wall("right", "0.14, 0.45, 0.091", '<rotate y="1" angle="-90"/><translate x="1" y="1"/>')
        + '''  <shape type="rectangle" id="light">
    <transform name="to_world"><scale value="0.25"/><rotate x="1" angle="90"/><translate y="1.99"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0, 0, 0"/></bsdf>
    <emitter type="area"><rgb name="radiance" value="17, 12, 4"/></emitter>
  </shape>
  <shape type="sphere" id="ball">
    <point name="center" x="0.3" y="0.4" z="-0.2"/><float name="radius" value="0.4"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf>
  </shape>
</scene>
''')


def cbox_xml(sensor_type="perspective", extra='\n    <float name="fov" value="40"/>', transform=LOOKAT,
             sensor=True) -> str:
    """The box with one sensor (or none)."""
    return CBOX.format(sensor=SENSOR.format(type=sensor_type, extra=extra, transform=transform) if sensor else "")
