// One ISAAC bench scene in Box2D v3, single-threaded: build, warm up, time, write the poses.
//
// usage: box2d_v3_scenes SCENE_FILE POSES_FILE [--substeps N]     (N: default 4, Box2D's)
//        box2d_v3_scenes --version
//
// SCENE_FILE is written by bench/peers/box2d_v3.py (export_scene) from the bench's own scene,
// every number in %.17g, so the doubles read here are the bench's bit for bit:
//     isaac-box2d-v3-scene 1
//     gravity <gx> <gy>          (m/s^2)
//     dt <dt>                    (s)
//     friction_on <0|1>
//     steps <warmup> <timed>
//     bodies <n>
//     then one line per body, in scene order:
//     <concrete 0|1> <density> <friction> <restitution> <px> <py> <angle> <vx> <vy> <w> <nv>
//         x1 y1 ... xn yn        (vertices about the area centroid, counter-clockwise)
// Box2D v3 is float32: each number is rounded to the nearest float when the world is built.
//
// World: gravity and dt from the scene; sleeping off (world and every body); workerCount = 1
// and no task callbacks, so Box2D runs every task inline on this thread; Box2D's defaults
// otherwise (contact hertz 30, damping ratio 10, contact push speed 3 m/s, continuous
// collision of dynamic against static bodies, friction mixing sqrt(a * b), restitution max).
//
// Timing: WARMUP steps, then TIMED steps inside one CLOCK_MONOTONIC block:
// ms_per_step = block / TIMED. cpu_ms_per_step is the same block on this thread's CPU clock.
// Memory: resident set size (/proc/self/statm) after reading the scene, after building the
// world and after the warm-up.
//
// Output: one JSON line on stdout; POSES_FILE holds one line per body, in scene order:
//     x0 y0 a0 vx0 vy0 w0 x1 y1 a1 vx1 vy1 w1
// the start (after building) and final centre of mass (m), angle (rad, atan2 of the rotation),
// velocity (m/s) and angular velocity (rad/s), in %.17g (each value exactly). The quality
// figures are computed from this file by bench/quality.py, the same code for every engine.
// A bad scene file: one line on stderr, exit 2. A polygon Box2D's hull would change: exit 3.

#define _POSIX_C_SOURCE 200809L

#include "box2d/box2d.h"
#include "box2d/collision.h"
#include "box2d/math_functions.h"

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

typedef struct SceneBody
{
	int concrete;
	double density, friction, restitution;
	double px, py, angle, vx, vy, w;
	int vertexCount;
	double vertices[2 * B2_MAX_POLYGON_VERTICES];
} SceneBody;

typedef struct Scene
{
	double gx, gy, dt;
	int frictionOn;
	int warmupSteps, timedSteps;
	int bodyCount;
	SceneBody* bodies;
} Scene;

typedef struct State
{
	double x, y, angle, vx, vy, w;
} State;

static void Fail( int status, const char* path, const char* what )
{
	fprintf( stderr, "box2d_v3_scenes: %s: %s\n", path, what );
	exit( status );
}

static void Expect( FILE* f, const char* key, const char* path )
{
	char word[64] = "";
	if ( fscanf( f, "%63s", word ) != 1 || strcmp( word, key ) != 0 )
	{
		char what[160];
		snprintf( what, sizeof( what ), "expected '%s', got '%s'", key, word );
		Fail( 2, path, what );
	}
}

static Scene LoadScene( const char* path )
{
	Scene s = { 0 };
	FILE* f = fopen( path, "r" );
	if ( f == NULL )
	{
		Fail( 2, path, "cannot open the scene file" );
	}

	int version = 0;
	Expect( f, "isaac-box2d-v3-scene", path );
	if ( fscanf( f, "%d", &version ) != 1 || version != 1 )
		Fail( 2, path, "unknown scene file version" );
	Expect( f, "gravity", path );
	if ( fscanf( f, "%lf %lf", &s.gx, &s.gy ) != 2 )
		Fail( 2, path, "bad gravity" );
	Expect( f, "dt", path );
	if ( fscanf( f, "%lf", &s.dt ) != 1 || !( s.dt > 0.0 ) )
		Fail( 2, path, "bad dt" );
	Expect( f, "friction_on", path );
	if ( fscanf( f, "%d", &s.frictionOn ) != 1 )
		Fail( 2, path, "bad friction_on" );
	Expect( f, "steps", path );
	if ( fscanf( f, "%d %d", &s.warmupSteps, &s.timedSteps ) != 2 || s.warmupSteps < 0 || s.timedSteps < 1 )
		Fail( 2, path, "bad steps (need warmup >= 0, timed >= 1)" );
	Expect( f, "bodies", path );
	if ( fscanf( f, "%d", &s.bodyCount ) != 1 || s.bodyCount < 1 )
		Fail( 2, path, "bad body count" );

	s.bodies = calloc( (size_t)s.bodyCount, sizeof( SceneBody ) );
	if ( s.bodies == NULL )
		Fail( 2, path, "out of memory" );
	for ( int i = 0; i < s.bodyCount; ++i )
	{
		SceneBody* b = s.bodies + i;
		int got = fscanf( f, "%d %lf %lf %lf %lf %lf %lf %lf %lf %lf %d", &b->concrete, &b->density, &b->friction,
						  &b->restitution, &b->px, &b->py, &b->angle, &b->vx, &b->vy, &b->w, &b->vertexCount );
		if ( got != 11 )
			Fail( 2, path, "truncated body line" );
		if ( b->vertexCount < 3 || b->vertexCount > B2_MAX_POLYGON_VERTICES )
			Fail( 2, path, "a body has fewer than 3 or more than B2_MAX_POLYGON_VERTICES vertices" );
		for ( int k = 0; k < 2 * b->vertexCount; ++k )
		{
			if ( fscanf( f, "%lf", b->vertices + k ) != 1 )
				Fail( 2, path, "truncated vertex list" );
		}
	}
	fclose( f );
	return s;
}

static double Seconds( clockid_t clock )
{
	struct timespec ts;
	clock_gettime( clock, &ts );
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

// resident set size (bytes): the second field of /proc/self/statm, in pages
static long ResidentBytes( void )
{
	long pages = 0;
	FILE* f = fopen( "/proc/self/statm", "r" );
	if ( f == NULL )
		return 0;
	if ( fscanf( f, "%*s %ld", &pages ) != 1 )
		pages = 0;
	fclose( f );
	return pages * sysconf( _SC_PAGESIZE );
}

static State GetState( b2BodyId id )
{
	b2Pos c = b2Body_GetWorldCenter( id );
	b2Rot q = b2Body_GetRotation( id );
	b2Vec2 v = b2Body_GetLinearVelocity( id );
	// libm atan2, not b2Rot_GetAngle (Box2D's fast approximation)
	State state = { c.x, c.y, atan2( q.s, q.c ), v.x, v.y, b2Body_GetAngularVelocity( id ) };
	return state;
}

static b2BodyId CreateBody( b2WorldId worldId, const Scene* s, int index, const char* path )
{
	const SceneBody* b = s->bodies + index;
	b2BodyDef bodyDef = b2DefaultBodyDef();
	bodyDef.type = b->concrete ? b2_staticBody : b2_dynamicBody;
	bodyDef.position = (b2Pos){ (float)b->px, (float)b->py };
	// libm cos and sin: b2MakeRot uses a fast approximation
	bodyDef.rotation = (b2Rot){ (float)cos( b->angle ), (float)sin( b->angle ) };
	if ( b->concrete == 0 )
	{
		bodyDef.linearVelocity = (b2Vec2){ (float)b->vx, (float)b->vy };
		bodyDef.angularVelocity = (float)b->w;
	}
	bodyDef.enableSleep = false;
	bodyDef.isAwake = true;
	b2BodyId bodyId = b2CreateBody( worldId, &bodyDef );

	b2Vec2 points[B2_MAX_POLYGON_VERTICES];
	for ( int k = 0; k < b->vertexCount; ++k )
		points[k] = (b2Vec2){ (float)b->vertices[2 * k], (float)b->vertices[2 * k + 1] };
	// Box2D takes a polygon through its hull; one that drops a vertex (welded or collinear) would
	// no longer be the bench's polygon
	b2Hull hull = b2ComputeHull( points, b->vertexCount );
	if ( hull.count != b->vertexCount )
	{
		char what[128];
		snprintf( what, sizeof( what ), "body %d: Box2D's hull has %d of its %d vertices", index, hull.count,
				  b->vertexCount );
		Fail( 3, path, what );
	}
	b2Polygon polygon = b2MakePolygon( &hull, 0.0f );
	b2ShapeDef shapeDef = b2DefaultShapeDef();
	shapeDef.density = (float)b->density;
	shapeDef.material.friction = s->frictionOn ? (float)b->friction : 0.0f;
	shapeDef.material.restitution = (float)b->restitution;
	b2CreatePolygonShape( bodyId, &shapeDef, &polygon );
	return bodyId;
}

static void WritePoses( const char* path, const State* start, const State* end, int count )
{
	FILE* f = fopen( path, "w" );
	if ( f == NULL )
		Fail( 2, path, "cannot write the poses file" );
	for ( int i = 0; i < count; ++i )
	{
		const State* states[2] = { start + i, end + i };
		for ( int k = 0; k < 2; ++k )
		{
			const State* q = states[k];
			fprintf( f, "%.17g %.17g %.17g %.17g %.17g %.17g%c", q->x, q->y, q->angle, q->vx, q->vy, q->w,
					 k == 0 ? ' ' : '\n' );
		}
	}
	fclose( f );
}

int main( int argc, char** argv )
{
	b2Version version = b2GetVersion();
	if ( argc == 2 && strcmp( argv[1], "--version" ) == 0 )
	{
		printf( "%d.%d.%d\n", version.major, version.minor, version.revision );
		return 0;
	}
	int substeps = 4;
	if ( argc == 5 && strcmp( argv[3], "--substeps" ) == 0 )
		substeps = atoi( argv[4] );
	else if ( argc != 3 )
	{
		fprintf( stderr, "usage: %s SCENE_FILE POSES_FILE [--substeps N] | --version\n", argv[0] );
		return 2;
	}
	if ( substeps < 1 )
		Fail( 2, argv[4], "--substeps takes a whole number >= 1" );
	const char* scenePath = argv[1];
	const char* posesPath = argv[2];

	Scene s = LoadScene( scenePath );
	long rssBefore = ResidentBytes();

	double b0 = Seconds( CLOCK_MONOTONIC );
	b2WorldDef worldDef = b2DefaultWorldDef();
	worldDef.gravity = (b2Vec2){ (float)s.gx, (float)s.gy };
	worldDef.enableSleep = false;
	worldDef.workerCount = 1;
	b2WorldId worldId = b2CreateWorld( &worldDef );
	b2BodyId* ids = malloc( (size_t)s.bodyCount * sizeof( b2BodyId ) );
	State* start = malloc( (size_t)s.bodyCount * sizeof( State ) );
	State* end = malloc( (size_t)s.bodyCount * sizeof( State ) );
	if ( ids == NULL || start == NULL || end == NULL )
		Fail( 2, scenePath, "out of memory" );
	for ( int i = 0; i < s.bodyCount; ++i )
		ids[i] = CreateBody( worldId, &s, i, scenePath );
	double buildSeconds = Seconds( CLOCK_MONOTONIC ) - b0;
	for ( int i = 0; i < s.bodyCount; ++i )
		start[i] = GetState( ids[i] );
	long rssBuilt = ResidentBytes();

	float dt = (float)s.dt;
	for ( int i = 0; i < s.warmupSteps; ++i )
		b2World_Step( worldId, dt, substeps );
	long rssWarm = ResidentBytes();

	double c0 = Seconds( CLOCK_THREAD_CPUTIME_ID );
	double t0 = Seconds( CLOCK_MONOTONIC );
	for ( int i = 0; i < s.timedSteps; ++i )
		b2World_Step( worldId, dt, substeps );
	double t1 = Seconds( CLOCK_MONOTONIC );
	double c1 = Seconds( CLOCK_THREAD_CPUTIME_ID );

	for ( int i = 0; i < s.bodyCount; ++i )
		end[i] = GetState( ids[i] );
	WritePoses( posesPath, start, end, s.bodyCount );
	b2Counters counters = b2World_GetCounters( worldId );
	struct rusage usage;
	getrusage( RUSAGE_SELF, &usage );

	printf( "{\"version\": \"%d.%d.%d\", \"bodies\": %d, \"substeps\": %d, \"warmup_steps\": %d, "
			"\"timed_steps\": %d, \"ms_per_step\": %.6g, \"cpu_ms_per_step\": %.6g, \"build_s\": %.6g, "
			"\"rss_before_build_bytes\": %ld, \"rss_built_bytes\": %ld, \"rss_warm_bytes\": %ld, "
			"\"peak_rss_bytes\": %ld, \"contacts\": %d}\n",
			version.major, version.minor, version.revision, s.bodyCount, substeps, s.warmupSteps, s.timedSteps,
			1000.0 * ( t1 - t0 ) / s.timedSteps, 1000.0 * ( c1 - c0 ) / s.timedSteps, buildSeconds, rssBefore,
			rssBuilt, rssWarm, 1024L * usage.ru_maxrss, counters.contactCount );

	b2DestroyWorld( worldId );
	free( end );
	free( start );
	free( ids );
	free( s.bodies );
	return 0;
}
