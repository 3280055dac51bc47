from setuptools import find_packages, setup

package_name = 'awalker_tools'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools', 'awalker_tracker', 'rosbags', 'matplotlib'],
    zip_safe=False,
    maintainer='awalker developers',
    maintainer_email='dev@awalker.invalid',
    description='awalker tools: the `awalker` command (convert, replay, info, simulate, synth, track, eval).',
    license='BSD-3-Clause',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'awalker = awalker_tools.cli:main',
            'awalker_replay = awalker_tools.replay:main',
        ],
    },
)
